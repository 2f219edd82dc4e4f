"""Passing vehicles parked partly in the lane: a lateral shift of the driver's path.

The spawner parks static vehicles at the roadside leaving only part of the lane free (section
2.2), so a lane follower that never leaves the centerline would queue behind them for ever.
Drivers pull over to the left (right-hand traffic) just enough to clear such a vehicle; the
shifted path is then checked for oncoming traffic like any other (corridor leader test).
"""

from __future__ import annotations

import numpy as np

from selfplaydrive.drivers._objects import nearest_objects


def parked_objects(objs: dict[str, np.ndarray], A: int) -> dict[str, np.ndarray]:
    """Static vehicles and terminated agents kept as obstacles (columns of `world_objects`)."""
    out = dict(objs)
    parked = np.zeros_like(objs["valid"])
    parked[:, A:] = ~objs["ped"][:, A:]
    parked[:, :A] = objs["obstacle"][:, :A]
    out["valid"] = objs["valid"] & parked
    return out


def nudge_shift(
    objs: dict, w_of: np.ndarray, ego: dict, path: dict, p, was_passing: np.ndarray
) -> np.ndarray:
    """Leftward shift [m] of each agent's path that clears the parked vehicles near its path
    (0 where none intrudes, or where clearing needs more than `p.max_nudge`).

    A parked vehicle counts when it lies from alongside the ego up to `p.nudge_range` ahead, on
    the right of the path by at least `p.nudge_min_offset`, and inside the corridor (ego half
    width + its extent across the path + `p.corridor_margin`).
    """
    N = len(w_of)
    A = N // len(objs["x"])
    o = nearest_objects(parked_objects(objs, A), w_of, A, ego, path, p.max_objects, ahead_only=False)
    pts, tan, arc = path["pts"], path["tan"], path["arc"]
    dx = o["x"][:, :, None] - pts[:, None, :, 0]
    dy = o["y"][:, :, None] - pts[:, None, :, 1]
    q = (dx**2 + dy**2).argmin(axis=2)[:, :, None]  # nearest path point of each object
    t = np.take_along_axis(np.broadcast_to(tan[:, None], (*dx.shape, 2)), q[..., None], 2)[:, :, 0]
    ex, ey = np.take_along_axis(dx, q, 2)[..., 0], np.take_along_axis(dy, q, 2)[..., 0]
    along = (
        np.take_along_axis(np.broadcast_to(arc[:, None, :], dx.shape), q, 2)[..., 0]
        + ex * t[..., 0]
        + ey * t[..., 1]
    )
    lat = -ex * t[..., 1] + ey * t[..., 0]  # + left of the path [m]
    cos_rel = np.abs(o["c"] * t[..., 0] + o["s"] * t[..., 1])
    ext = o["hw"] * cos_rel + o["hl"] * np.sqrt(np.maximum(0.0, 1.0 - cos_rel**2))
    clearance = ego["hw"][:, None] + ext + p.corridor_margin
    need = clearance + lat + p.nudge_extra  # left shift that clears a vehicle on the right
    near = (along > -(ego["hl"][:, None] + o["hl"] + 1.0)) & (along < p.nudge_range)
    right = lat <= -p.nudge_min_offset
    intrude = o["valid"] & near & (np.abs(lat) < clearance)
    blocked = intrude & ~right  # centred or on the left: no pulling over, keep the gap
    passing = intrude & right
    shift = np.where(passing, need, 0.0).max(axis=1)
    gap = np.where(passing, along - ego["hl"][:, None] - o["hl"], np.inf).min(axis=1)
    # a pass needs room to move over: started only with `nudge_start_gap` to the parked vehicle
    # (a car already passing, `was_passing`, goes on)
    room = (gap >= p.nudge_start_gap) | was_passing
    return np.where(blocked.any(axis=1) | (shift > p.max_nudge) | ~room, 0.0, shift)


def shifted(path: dict, shift: np.ndarray) -> dict:
    """`path` with its points moved `shift` [m] to the left of the path direction."""
    out = dict(path)
    normal = np.stack([-path["tan"][..., 1], path["tan"][..., 0]], axis=-1)
    out["pts"] = path["pts"] + shift[:, None, None] * normal
    return out
