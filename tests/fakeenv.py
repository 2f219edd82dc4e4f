"""A one-world stand-in for `VecEnv` with hand-set state, for the per-step recorders of
`selfplaydrive.eval` (diversity, collisions): they read only `state`, `reward_mask` and sizes."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np


def one_world_env(static_xy: tuple[float, float], **agents: np.ndarray) -> SimpleNamespace:
    """One world whose agents have the given `state` fields (x, y, heading, events, lane_* ...;
    all of one length N), every slot valid, active and acting, 4.5 x 2 m boxes unless `length` /
    `width` are given, and one 4 x 2 m static vehicle at `static_xy` heading along +x."""
    n = len(agents["x"])
    fields = {
        "length": np.full(n, 4.5, np.float32),
        "width": np.full(n, 2.0, np.float32),
        "agent_valid": np.ones(n, np.uint8),
        "active": np.ones(n, np.uint8),
        "obstacle": np.zeros(n, np.uint8),
        "st_valid": np.ones(1, np.uint8),
        "st_x": np.array([static_xy[0]], np.float32),
        "st_y": np.array([static_xy[1]], np.float32),
        "st_len": np.array([4.0], np.float32),
        "st_wid": np.array([2.0], np.float32),
        "st_cos": np.ones(1, np.float32),
        "st_sin": np.zeros(1, np.float32),
    }
    fields.update(agents)
    return SimpleNamespace(
        state=SimpleNamespace(**fields),
        reward_mask=np.ones(n, bool),
        num_agents=n,
        num_worlds=1,
        agents_per_world=n,
    )
