"""Digest of a seeded rollout: a sha256 over every state buffer after every step.

The pinned-digest regression test (tests/sim/test_digests.py) compares it against values
recorded before a refactor, so a change that alters the paper's rollout by one bit is caught
(a plug-in architecture must not move the paper configuration; paper sections 2.4, 2.6).
"""

from __future__ import annotations

import hashlib
from typing import Any

import numpy as np

# the buffers of the paper's state that existed when the digests were pinned (sim/buffers.py),
# in a fixed order; buffers added later (a physics model's own state, ...) are not hashed, so
# adding one does not move the pinned values. `cand` / `cand_d` are per-world scratch.
DIGEST_BUFFERS = (
    "x", "y", "heading", "hcos", "hsin", "speed", "px", "py", "pheading", "length", "width",
    "a_long", "a_lat", "coeffs", "hidden", "waypoints", "num_wp", "wp_idx", "active", "obstacle",
    "lane_s", "lane_alpha", "lane_valid", "events", "ever", "road_idx", "road_n", "obj_rows",
    "road_rows", "road_r", "road_x", "road_y", "act_i", "act_f", "reward", "terms", "term", "trunc",
    "obs", "final_obs", "st_x", "st_y", "st_cos", "st_sin", "st_len", "st_wid", "st_valid",
    "ped_path", "ped_np", "ped_speed", "ped_start", "ped_len", "ped_wid", "ped_valid", "ped_here",
    "ped_x", "ped_y", "ped_px", "ped_py", "ped_cos", "ped_sin", "ped_vx", "ped_vy", "light_state",
    "light_time", "map_id", "step", "max_steps", "lights_on", "done", "rng_key", "rng_ctr",
    "term_sum", "ev_count", "dist",
)  # fmt: skip


def rollout_digest(env: Any, steps: int = 400, seed: int = 0, action_seed: int = 1) -> str:
    """sha256 (hex) of the env's state buffers after reset and after each of `steps` steps
    driven by seeded uniform random actions (drawn from the env's action space shape).

    Args:
        env: A `VecEnv`.
        steps: Steps of the rollout.
        seed: Seed of `env.reset`.
        action_seed: Seed of the action generator.
    """
    rng = np.random.default_rng(action_seed)
    h = hashlib.sha256()
    b = env.buffers

    def update() -> None:
        for name in DIGEST_BUFFERS:
            h.update(np.ascontiguousarray(b[name]).tobytes())

    env.reset(seed=seed)
    update()
    space = env.action_space
    nvec = getattr(space, "nvec", None)
    for _ in range(steps):
        if nvec is not None:
            a = np.stack([rng.integers(0, int(n), env.num_agents) for n in nvec], axis=1).astype(np.int64)
        else:
            lo, hi = space.low, space.high
            a = (lo + (hi - lo) * rng.random((env.num_agents, len(lo)))).astype(np.float32)
        env.step(a)
        update()
    return h.hexdigest()
