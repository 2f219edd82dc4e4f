"""One rank of the data-parallel test (tests/trainers/test_ddp.py), started by torchrun.

Each rank trains the same small model on its own env (the trainer seeds it `seed + rank`) for
two updates with Gloo, then saves its parameters and first observations to `<out>/rank<r>.pt`.
"""

import os
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from ppo_helpers import lane_env

from selfplaydrive.models import DeepSetsModel
from selfplaydrive.trainers import PPOConfig, PPOTrainer


def main(out: Path) -> None:
    torch.manual_seed(1000 + int(os.environ["RANK"]))  # ranks start different
    env = lane_env(num_worlds=2, seed=0)
    model = DeepSetsModel(env.layout, input_size=8, hidden_size=16, lstm_size=16)
    cfg = PPOConfig(
        total_steps=2 * 8 * env.num_agents,
        rollout_length=8,
        num_epochs=1,
        num_minibatches=1,
        device="cpu",
        torch_threads=1,
        progress_bar=False,
        checkpoint_interval=0,
        eval_episodes=0,
        seed=0,
    )
    start = {k: v.clone() for k, v in model.state_dict().items()}  # before DDP's broadcast
    trainer = PPOTrainer(env, model, cfg)
    trainer.train()
    torch.save(
        {
            "rank": trainer.dist.rank,
            "world_size": trainer.dist.world_size,
            "start": start,
            "end": model.state_dict(),
            "first_obs": trainer.storage.obs[0].clone(),
        },
        out / f"rank{trainer.dist.rank}.pt",
    )


if __name__ == "__main__":
    main(Path(sys.argv[1]))
