"""Helpers shared by the command-line examples (04, 05): the tiny settings and how to call the
`selfplaydrive` command. Not an example itself."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

# Overrides that shrink a training run to a few seconds on a laptop CPU: one world of 8 agents
# with 2 s episodes on a small generated town, a small model, 2 updates of 16 steps.
TINY_OVERRIDES = (
    "trainer.total_steps=256",
    "trainer.rollout_length=16",
    "trainer.num_epochs=1",
    "trainer.eval_episodes=0",
    "trainer.progress_bar=false",
    "trainer.checkpoint_interval=0",
    "env.num_worlds=1",
    "spawner.num_agents=8",
    "spawner.num_static=8",
    "spawner.num_pedestrians=2",
    "spawner.episode_lengths=[2.0]",
    "spawner.min_region_lane_length=300",
    "map=procedural",
    "map.size=400",
    "map.num_roundabouts=0",
    "obs.max_objects=16",
    "obs.max_road=64",
    "model.input_size=16",
    "model.hidden_size=32",
    "model.lstm_size=32",
)


def is_tiny(flag: bool) -> bool:
    """The --tiny flag or SELFPLAYDRIVE_EXAMPLE_TINY=1."""
    return flag or os.environ.get("SELFPLAYDRIVE_EXAMPLE_TINY") == "1"


def selfplaydrive_command() -> list[str]:
    """The `selfplaydrive` script, or `python -m selfplaydrive.cli` when it is not on PATH."""
    exe = shutil.which("selfplaydrive")
    return [exe] if exe else [sys.executable, "-m", "selfplaydrive.cli"]


def run(args: list[str]) -> None:
    """Run a command, echo it, exit with its code on failure."""
    print("$ " + " ".join(args), flush=True)
    done = subprocess.run(args, check=False)
    if done.returncode != 0:
        sys.exit(f"command failed with exit code {done.returncode}")
