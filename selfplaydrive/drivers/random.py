"""`RandomDriver`: uniformly random actions (the baseline the rule-based driver is measured
against in tests/drivers)."""

from __future__ import annotations

import numpy as np


class RandomDriver:
    """Uniform random actions for every agent slot of `env` (a `VecEnv`).

    Args:
        env: The native env.
        seed: Seed of the driver's own generator.
    """

    def __init__(self, env, seed: int | None = 0) -> None:
        self.env = env
        self.rng = np.random.default_rng(seed)

    def reset(self) -> None:
        """Nothing to forget (the generator keeps running)."""

    def __call__(self, obs: np.ndarray | None = None) -> np.ndarray:
        return self.act()

    def act(self) -> np.ndarray:
        """(N, 2) uniform actions: table indices (discrete) or values within the Box."""
        t, n = self.env.action_table, self.env.num_agents
        if t.discrete:
            return np.stack(
                [self.rng.integers(0, len(t.accel), n), self.rng.integers(0, len(t.steer), n)], axis=1
            )
        return self.rng.uniform(-t.high, t.high, size=(n, 2)).astype(np.float32)
