"""Check that two forms of a reward term agree (docs/components.md "Promote a Python term").

`compare_terms` steps the same random rollout twice, once with each form as an extra column
next to nothing else, and compares the columns of the agents that acted, step by step.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def term_column(term: Any, maps: Any, steps: int = 50, seed: int = 0, num_worlds: int = 2) -> np.ndarray:
    """(steps, N) values of `term` (weight 1) on a fixed rollout of the paper spawner with
    random mostly-forward actions; 0 where the agent did not act."""
    from selfplaydrive.rewards.components import LinearReward
    from selfplaydrive.scenario.spawner import PaperSpawner
    from selfplaydrive.sim.vec_env import VecEnv

    env = VecEnv(
        maps, PaperSpawner(), num_worlds, seed=seed, reward=LinearReward({term.name: 1.0}, terms=[term])
    )
    env.reset(seed)
    rng = np.random.default_rng(seed)
    out = np.zeros((steps, env.num_agents), dtype=np.float32)
    for k in range(steps):
        acts = np.stack([rng.integers(3, 7, env.num_agents), rng.integers(0, 13, env.num_agents)], axis=1)
        env.step(acts)
        out[k] = np.where(env.reward_mask, env.reward_terms[:, 0], 0.0)
    return out


def compare_terms(
    reference: Any,
    candidate: Any,
    maps: Any,
    steps: int = 50,
    seed: int = 0,
    rtol: float = 1e-6,
    atol: float = 1e-7,
    num_worlds: int = 2,
) -> float:
    """Assert that `candidate` (e.g. a numba or Cython `KernelTerm`) gives the values of
    `reference` (e.g. the NumPy term it was ported from) to float32 rounding.

    Args:
        reference, candidate: Terms of one name (any form).
        maps: A `RoadMap` or a sequence of them.
        steps, seed, num_worlds: The rollout.
        rtol, atol: Tolerances of `numpy.testing.assert_allclose`.

    Returns:
        The largest absolute difference.

    Raises:
        AssertionError: The first step and agent slot where they differ, with both values.
    """
    if reference.name != candidate.name:
        raise ValueError(f"compare_terms: the terms are named {reference.name!r} and {candidate.name!r}")
    a = term_column(reference, maps, steps, seed, num_worlds)
    b = term_column(candidate, maps, steps, seed, num_worlds)
    bad = ~np.isclose(b, a, rtol=rtol, atol=atol)
    if bad.any():
        k, i = (int(v) for v in np.argwhere(bad)[0])
        raise AssertionError(
            f"reward term {reference.name!r}: step {k}, agent slot {i}: reference {a[k, i]!r}, "
            f"candidate {b[k, i]!r} ({int(bad.sum())} of {bad.size} values differ)"
        )
    return float(np.max(np.abs(b - a))) if a.size else 0.0


__all__ = ["compare_terms", "term_column"]
