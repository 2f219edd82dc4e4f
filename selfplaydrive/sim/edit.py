"""Public edits of a running `VecEnv`: new routes and teleported poses (paper section 5
evaluations), behind `VecEnv.set_waypoints` / `VecEnv.set_poses`.

Long-form evaluation gives an agent that reached its last waypoint a new route; log replay
moves the non-ego agents to their logged poses after every step. Both write agent rows of the
state (sim/schema.py: `waypoints`, `num_wp`, `wp_idx`; `x`, `y`, `heading`, `hcos`, `hsin`,
`speed`) that the kernels read at the next step. Everything is checked before anything is
written, so a bad call leaves the env unchanged.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from selfplaydrive.sim.vec_env import VecEnv

_PI32 = float(np.float32(np.pi))  # pi rounded to float32 (a float32 heading of pi is above np.pi)


def agent_indices(env: VecEnv, agents: object) -> np.ndarray:
    """`agents` as a 1-D int64 array of distinct flat agent indices i = w * A + a.

    Raises:
        ValueError: Not integers, not 1-D, out of [0, num_agents) or repeated.
    """
    idx = np.asarray(agents)
    if idx.ndim != 1 or (idx.size and idx.dtype.kind not in "iu"):
        raise ValueError(f"agents: expected 1-D integer agent indices, got {idx.dtype} {idx.shape}")
    idx = idx.astype(np.int64)
    if idx.size and not (idx.min() >= 0 and idx.max() < env.num_agents):
        bad = int(idx[(idx < 0) | (idx >= env.num_agents)][0])
        raise ValueError(f"agents: expected indices in [0, {env.num_agents}), got {bad}")
    if len(np.unique(idx)) != len(idx):
        raise ValueError(f"agents: expected distinct indices, got {idx.tolist()}")
    return idx


def set_waypoints(env: VecEnv, agents: object, waypoints: object, num_waypoints: object) -> None:
    """Give `agents` new routes: rows of `waypoints` and `num_wp`, and `wp_idx` = 0 (the first
    new waypoint is the current one). Docs: `VecEnv.set_waypoints`."""
    idx = agent_indices(env, agents)
    K = env.dims.K
    wps = np.asarray(waypoints)
    count = np.asarray(num_waypoints)
    if wps.shape != (len(idx), K, 2) or wps.dtype.kind not in "iuf":
        raise ValueError(
            f"waypoints: expected a numeric array of shape ({len(idx)}, {K}, 2) (agents, max_waypoints, xy), "
            f"got {wps.dtype} {wps.shape}"
        )
    if count.shape != (len(idx),) or (count.size and count.dtype.kind not in "iu"):
        raise ValueError(f"num_waypoints: expected {len(idx)} integers, got {count.dtype} {count.shape}")
    if count.size and not (count.min() >= 0 and count.max() <= K):
        k = int(np.flatnonzero((count < 0) | (count > K))[0])
        raise ValueError(f"num_waypoints: expected counts in [0, {K}], got {int(count[k])} (agent {idx[k]})")
    used = np.arange(K)[None, :] < count[:, None]
    bad = (used & ~np.isfinite(wps).all(axis=-1)).any(axis=1)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise ValueError(f"waypoints: expected finite points [m] within num_waypoints, got {wps[k].tolist()}")
    b = env.buffers
    b["waypoints"][idx] = wps
    b["num_wp"][idx] = count
    b["wp_idx"][idx] = 0


def set_poses(env: VecEnv, agents: object, xy: object, heading: object, speed: object) -> None:
    """Move `agents` to new poses: `x`, `y`, `heading`, its cached `hcos` / `hsin`, and `speed`.
    Docs: `VecEnv.set_poses`."""
    idx = agent_indices(env, agents)
    n = len(idx)
    xy = np.asarray(xy, dtype=np.float64)
    heading = np.asarray(heading, dtype=np.float64)
    speed = np.asarray(speed, dtype=np.float64)
    for name, a, shape in (("xy", xy, (n, 2)), ("heading", heading, (n,)), ("speed", speed, (n,))):
        if a.shape != shape:
            raise ValueError(f"{name}: expected shape {shape} (one row per agent), got {a.shape}")
        if not np.isfinite(a).all():
            raise ValueError(f"{name}: expected finite values, got {a[~np.isfinite(a)][0]}")
    if n and np.abs(heading).max() > _PI32:
        raise ValueError(f"heading: expected radians in [-pi, pi], got {heading[np.abs(heading) > _PI32][0]}")
    if n and speed.min() < 0:
        raise ValueError(f"speed: expected speeds >= 0 [m/s], got {speed.min()}")
    b = env.buffers
    b["x"][idx] = xy[:, 0]
    b["y"][idx] = xy[:, 1]
    b["heading"][idx] = heading
    b["hcos"][idx] = np.cos(heading)
    b["hsin"][idx] = np.sin(heading)
    b["speed"][idx] = speed
