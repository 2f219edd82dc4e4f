"""Helper shared by examples 06-08 (one reward term written three ways): drive random actions
in an env whose reward is the paper's eight terms plus the example's term, and print each
column's sum. Not an example itself."""

from __future__ import annotations

import os
import sys

import numpy as np

from selfplaydrive import make_env
from selfplaydrive.rewards import TERM_NAMES, LinearReward


def tiny(argv: list[str]) -> bool:
    """--tiny on the command line or SELFPLAYDRIVE_EXAMPLE_TINY=1: a few seconds."""
    return "--tiny" in argv or os.environ.get("SELFPLAYDRIVE_EXAMPLE_TINY") == "1"


def drive(term: object, weight: float = 1.0, small: bool = False, seed: int = 0) -> object:
    """Step an env with the paper's terms plus `term` (weight `weight`) under random actions and
    print the sum of every reward column over the agents that acted. Returns the env."""
    reward = LinearReward({**{name: 1.0 for name in TERM_NAMES}, term.name: weight}, terms=[term])
    env = make_env("default", num_worlds=2 if small else 16, reward=reward, seed=seed)
    env.reset(seed)
    rng = np.random.default_rng(seed)
    sums = np.zeros(len(env.term_names))
    steps = 40 if small else 400
    for _ in range(steps):
        # mostly accelerating (indices 4-6 of the 7 accelerations), straight-ish steering
        env.step(np.stack([rng.integers(4, 7, env.num_agents), rng.integers(4, 9, env.num_agents)], axis=1))
        sums += env.reward_terms[env.reward_mask].sum(axis=0)
    print(
        f"reward columns of {env.num_agents} agents over {steps} steps ({term.name}: {type(term).__name__})"
    )
    for name, value in zip(env.term_names, sums, strict=True):
        print(f"  {name:12s} {value:+12.5f}")
    sys.stdout.flush()
    return env
