"""`StaticDriver`: every vehicle brakes fully with zero steering, so it stops and stays."""

from __future__ import annotations

import numpy as np


def static_actions(table, n: int) -> np.ndarray:
    """(n, 2) actions of full braking and zero steering in the space of action `table`
    (`DiscreteActions`: the most negative acceleration and the steering entry nearest 0)."""
    if table.discrete:
        a = np.empty((n, 2), dtype=np.int64)
        a[:, 0] = int(np.argmin(table.accel))
        a[:, 1] = int(np.argmin(np.abs(table.steer)))
        return a
    # a box: zero where the bounds allow it, the lowest value of column 0 (full braking for the
    # (accel, steer) box; no forward motion for the delta model's (dx, dy, dyaw))
    a = np.tile(np.clip(0.0, table.low, table.high).astype(np.float32), (n, 1))
    a[:, 0] = table.low[0]
    return a


class StaticDriver:
    """Actions that stop every agent of `env` (a `VecEnv`) and keep it standing."""

    def __init__(self, env) -> None:
        self.env = env

    def reset(self) -> None:
        """Nothing to forget (stateless)."""

    def __call__(self, obs: np.ndarray | None = None) -> np.ndarray:
        return self.act()

    def act(self) -> np.ndarray:
        """(N, 2) full-braking, zero-steering actions."""
        return static_actions(self.env.action_table, self.env.num_agents)
