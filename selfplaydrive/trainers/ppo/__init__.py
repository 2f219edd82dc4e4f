"""PPO-clip over the native `VecEnv` buffers: config, storage, GAE, losses, trainer."""

from selfplaydrive.trainers.ppo.advantage import compute_gae
from selfplaydrive.trainers.ppo.config import PPOConfig
from selfplaydrive.trainers.ppo.trainer import PPOTrainer

__all__ = ["PPOConfig", "PPOTrainer", "compute_gae"]
