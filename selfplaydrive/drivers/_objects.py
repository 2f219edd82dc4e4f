"""Objects of each world as seen by the rule-based driver, and the nearest one in each agent's
path corridor (vectorised over agents, objects and path points)."""

from __future__ import annotations

import numpy as np


def world_objects(st, A: int) -> dict[str, np.ndarray]:
    """Every object of every world as (W, O) arrays: other agents (active or kept as
    obstacles), static vehicles, pedestrians present; O = A + S + P.

    Keys: x, y [m], c, s (heading cos/sin), hl, hw (half length/width [m]), vx, vy [m/s],
    valid (bool), ped (bool, is a pedestrian), obstacle (bool, a terminated agent kept standing).
    """
    W = len(st.step)

    def rows(a: np.ndarray) -> np.ndarray:
        return np.asarray(a, dtype=np.float64).reshape(W, -1)

    moving = rows(st.active)  # obstacles (terminated, kept) stand still
    ag_v = rows(st.speed) * moving
    ag_c, ag_s = rows(st.hcos), rows(st.hsin)
    n_st, n_ped = rows(st.st_x).shape[1], rows(st.ped_x).shape[1]
    cat = np.concatenate
    return dict(
        x=cat([rows(st.x), rows(st.st_x), rows(st.ped_x)], axis=1),
        y=cat([rows(st.y), rows(st.st_y), rows(st.ped_y)], axis=1),
        c=cat([ag_c, rows(st.st_cos), rows(st.ped_cos)], axis=1),
        s=cat([ag_s, rows(st.st_sin), rows(st.ped_sin)], axis=1),
        hl=cat([rows(st.length), rows(st.st_len), rows(st.ped_len)], axis=1) / 2.0,
        hw=cat([rows(st.width), rows(st.st_wid), rows(st.ped_wid)], axis=1) / 2.0,
        vx=cat([ag_v * ag_c, np.zeros((W, n_st)), rows(st.ped_vx)], axis=1),
        vy=cat([ag_v * ag_s, np.zeros((W, n_st)), rows(st.ped_vy)], axis=1),
        valid=cat(
            [
                (rows(st.active) + rows(st.obstacle)) > 0,
                rows(st.st_valid) > 0,
                (rows(st.ped_valid) * rows(st.ped_here)) > 0,
            ],
            axis=1,
        ),
        ped=cat([np.zeros((W, A + n_st), bool), np.ones((W, n_ped), bool)], axis=1),
        obstacle=cat([rows(st.obstacle) > 0, np.zeros((W, n_st + n_ped), bool)], axis=1),
    )


def corridor_leader(
    objs: dict[str, np.ndarray], w_of: np.ndarray, ego: dict, path: dict, p
) -> tuple[np.ndarray, np.ndarray]:
    """Bumper-to-bumper gap [m] to, and speed along the path [m/s] of, the nearest object
    ahead inside each agent's path corridor (inf, 0 when none; negative speed: oncoming).

    An object is in the corridor when its centre lies within ego half width + the object's
    extent across the path + a margin of some path point ahead of the agent.
    """
    N = len(w_of)
    A = N // len(objs["x"])
    o = nearest_objects(objs, w_of, A, ego, path, p.max_objects)
    pts, tan = path["pts"], path["tan"]  # (N, Q, 2)
    dx = o["x"][:, :, None] - pts[:, None, :, 0]
    dy = o["y"][:, :, None] - pts[:, None, :, 1]
    d2 = dx**2 + dy**2  # (N, k, Q) squared distances [m^2]
    cos_rel = np.abs(o["c"][:, :, None] * tan[:, None, :, 0] + o["s"][:, :, None] * tan[:, None, :, 1])
    sin_rel = np.sqrt(np.maximum(0.0, 1.0 - cos_rel**2))
    lat_ext = o["hw"][:, :, None] * cos_rel + o["hl"][:, :, None] * sin_rel
    margin = np.where(o["ped"], p.ped_margin, p.corridor_margin)[:, :, None]
    inside = d2 < (ego["hw"][:, None, None] + lat_ext + margin) ** 2
    hit = inside & o["valid"][:, :, None]
    qn = np.where(hit, d2, np.inf).argmin(axis=2)  # nearest path point of each object
    any_hit = hit.any(axis=2)
    take = qn[:, :, None]
    arc = np.take_along_axis(np.broadcast_to(path["arc"][:, None, :], d2.shape), take, 2)[..., 0]
    tq = np.take_along_axis(np.broadcast_to(tan[:, None], (*d2.shape, 2)), take[..., None], 2)[:, :, 0]
    along = (
        np.take_along_axis(dx, take, 2)[..., 0] * tq[..., 0]
        + np.take_along_axis(dy, take, 2)[..., 0] * tq[..., 1]
    )
    long_ext = np.take_along_axis(o["hl"][:, :, None] * cos_rel + o["hw"][:, :, None] * sin_rel, take, 2)[
        ..., 0
    ]
    gap = np.where(any_hit, arc + along - ego["hl"][:, None] - long_ext, np.inf)
    v_along = o["vx"] * tq[..., 0] + o["vy"] * tq[..., 1]
    k = gap.argmin(axis=1)
    r = np.arange(N)
    g = gap[r, k]
    # an oncoming object has a negative speed along the path: IDM then brakes for the closing
    # speed, not only for the gap
    return g, np.where(np.isfinite(g), v_along[r, k], 0.0)


def nearest_objects(
    objs: dict, w_of: np.ndarray, A: int, ego: dict, path: dict, k: int, ahead_only: bool = True
) -> dict:
    """The k nearest valid objects ahead of each agent within reach of its path, (N, k) arrays
    (keeps the (N, O, Q) corridor test small)."""
    N = len(w_of)
    x, y = objs["x"][w_of], objs["y"][w_of]
    rx, ry = x - ego["x"][:, None], y - ego["y"][:, None]
    d2 = rx**2 + ry**2
    reach = path["arc"][:, -1] + 10.0
    ok = objs["valid"][w_of].copy()
    if ahead_only:
        ok &= rx * ego["c"][:, None] + ry * ego["s"][:, None] > 0.0
    ok &= d2 < (reach**2)[:, None]
    if objs["x"].shape[1] >= A:
        ok[np.arange(N), np.arange(N) % A] = False  # not oneself (agents come first)
    key = np.where(ok, d2, np.inf)
    k = min(k, key.shape[1])
    idx = np.argpartition(key, k - 1, axis=1)[:, :k]
    out = {name: np.take_along_axis(v[w_of], idx, axis=1) for name, v in objs.items()}
    out["valid"] = np.take_along_axis(ok, idx, axis=1)
    return out


def crossing_gap(objs: dict, w_of: np.ndarray, ego: dict, path: dict, p) -> np.ndarray:
    """Gap [m] to the first point of each agent's path that a crossing vehicle reaches first.

    Other moving agents are extrapolated along their heading at `p.predict_times`; a predicted
    box centre inside the corridor of a crossing vehicle (|cos| of the relative heading below
    `p.crossing_cos`) that arrives there before the ego (time to the point at the ego's current
    speed, at least 1 m/s) makes the ego stop short of that point: a simple right of way for
    junctions, where lanes cross (section 2.1 treats every stop line as a yield line).
    """
    N = len(w_of)
    A = N // len(objs["x"])
    o = nearest_objects(_movers(objs, A), w_of, A, ego, path, p.max_objects, ahead_only=False)
    pts, tan, arc = path["pts"], path["tan"], path["arc"]
    v_e = np.maximum(ego["v"], 1.0)
    tau = np.asarray(p.predict_times, dtype=np.float64)[None, None, :, None]  # (1, 1, T, 1)
    x = o["x"][:, :, None, None] + o["vx"][:, :, None, None] * tau  # (N, k, T, 1)
    y = o["y"][:, :, None, None] + o["vy"][:, :, None, None] * tau
    d2 = (x - pts[:, None, None, :, 0]) ** 2 + (y - pts[:, None, None, :, 1]) ** 2  # (N, k, T, Q)
    cos_rel = np.abs(o["c"][:, :, None] * tan[:, None, :, 0] + o["s"][:, :, None] * tan[:, None, :, 1])
    sin_rel = np.sqrt(np.maximum(0.0, 1.0 - cos_rel**2))
    ext = o["hw"][:, :, None] * cos_rel + o["hl"][:, :, None] * sin_rel  # (N, k, Q)
    reach = ego["hw"][:, None, None] + ext + p.corridor_margin
    crossing = (cos_rel < p.crossing_cos) & o["valid"][:, :, None]
    first = (arc / v_e[:, None])[:, None, None, :] > tau  # the other one is there before the ego
    hit = (d2 < (reach**2)[:, :, None, :]) & first & crossing[:, :, None, :]
    a = np.where(hit.any(axis=2), (arc[:, None, :] - ext), np.inf).min(axis=(1, 2))
    best = a - ego["hl"]
    return best


def _movers(objs: dict, A: int) -> dict:
    """Only the moving agents (the first A columns, speed above 0.5 m/s)."""
    out = {k: v[:, :A] for k, v in objs.items()}
    out["valid"] = out["valid"] & (np.hypot(out["vx"], out["vy"]) > 0.5)
    return out
