"""One rank of the data-parallel test (tests/trainers/test_ddp.py), started by torchrun.

Each rank trains the same small model on its own env (the trainer seeds it `seed + rank`) for
two updates with Gloo, then saves its parameters and first observations to `<out>/rank<r>.pt`.

With `--resume-mismatch`, each rank instead trains two updates into `<out>/run` through
`train_run`, rank 1 drops its update-2 checkpoints (a node stopped between the ranks' saves),
and both resume: each saves the error it got to `<out>/error.rank<r>.txt`.

`FirstObservations` is a trainer callback for the CLI runs of tests/trainers/test_multinode.py
(importable with this folder on PYTHONPATH).
"""

import dataclasses
import os
import sys
import warnings
from pathlib import Path

import torch
import torch.distributed as td

sys.path.insert(0, str(Path(__file__).resolve().parent))
from ppo_helpers import lane_env

from selfplaydrive.errors import CheckpointError
from selfplaydrive.models import DeepSetsModel
from selfplaydrive.trainers import PPOConfig, PPOTrainer
from selfplaydrive.trainers.ppo.dist import exit_distributed
from selfplaydrive.trainers.ppo.logging import ProgressLogger
from selfplaydrive.trainers.run import train_run


class FirstObservations:
    """Trainer callback: after the first update of a fresh run, save the rank, the env's seed and
    the first rollout's first observations (the reset's) to `<out>/first_obs.rank<r>.pt`.

    Args:
        out: Folder of the files (created).
    """

    def __init__(self, out: str) -> None:
        self.out = Path(out)

    def on_update(self, trainer: PPOTrainer, metrics: dict[str, float]) -> None:
        if trainer.update_idx != 1:
            return
        rank = trainer.dist.rank
        self.out.mkdir(parents=True, exist_ok=True)
        record = {"rank": rank, "env_seed": trainer.env._seed, "obs": trainer.storage.obs[0].cpu().clone()}
        torch.save(record, self.out / f"first_obs.rank{rank}.pt")


def tiny_config(updates: int, checkpoint_interval: int, slots: int) -> PPOConfig:
    """Two-update-sized PPO settings for `slots` agent slots (rollouts of 8 steps)."""
    return PPOConfig(
        total_steps=updates * 8 * slots,
        rollout_length=8,
        num_epochs=1,
        num_minibatches=1,
        device="cpu",
        torch_threads=1,
        progress_bar=False,
        checkpoint_interval=checkpoint_interval,
        eval_episodes=0,
        seed=0,
    )


def main(out: Path) -> None:
    torch.manual_seed(1000 + int(os.environ["RANK"]))  # ranks start different
    env = lane_env(num_worlds=2, seed=0)
    model = DeepSetsModel(env.layout, input_size=8, hidden_size=16, lstm_size=16)
    # update_threads is an option for one process: under torchrun the trainer turns it off, warns
    cfg = dataclasses.replace(tiny_config(2, 0, env.num_agents), update_threads=2)
    start = {k: v.clone() for k, v in model.state_dict().items()}  # before DDP's broadcast
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        trainer = PPOTrainer(env, model, cfg)
    trainer.train()
    torch.save(
        {
            "rank": trainer.dist.rank,
            "world_size": trainer.dist.world_size,
            "start": start,
            "end": model.state_dict(),
            "first_obs": trainer.storage.obs[0].clone(),
            "update_threads": trainer.update_threads,
            "warnings": [str(w.message) for w in caught],
        },
        out / f"rank{trainer.dist.rank}.pt",
    )


def resume_mismatch(out: Path) -> None:
    rank = int(os.environ["RANK"])
    env = lane_env(num_worlds=2, seed=0)
    model = DeepSetsModel(env.layout, input_size=8, hidden_size=16, lstm_size=16)
    run = out / "run"
    train_run(env, model, tiny_config(2, 1, env.num_agents), run, logger=ProgressLogger)
    td.barrier()
    if rank == 1:
        for name in ("ckpt_0000002.rank1.pt", "final.rank1.pt"):
            (run / "checkpoints" / name).unlink()
    td.barrier()
    try:
        train_run(env, model, tiny_config(4, 1, env.num_agents), run, resume=run, logger=ProgressLogger)
    except CheckpointError as exc:
        (out / f"error.rank{rank}.txt").write_text(str(exc))


if __name__ == "__main__":
    if sys.argv[1] == "--resume-mismatch":
        resume_mismatch(Path(sys.argv[2]))
    else:
        main(Path(sys.argv[1]))
    exit_distributed(0)  # an exit through the interpreter's teardown sometimes aborted in Gloo
