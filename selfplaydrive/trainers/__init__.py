"""Trainers: the library's own PPO (`ppo/`) and the run-folder entry point (`run.train_run`)."""

from selfplaydrive.trainers.ppo import PPOConfig, PPOTrainer
from selfplaydrive.trainers.run import train_run

__all__ = ["PPOConfig", "PPOTrainer", "train_run"]
