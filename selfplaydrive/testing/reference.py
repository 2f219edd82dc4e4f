"""Plain NumPy references of the simulator kernels (_sim/*.pyx), written independently and
in float64 for clarity, compared with the kernels on random states in tests/sim.

Each function documents the same rule as its kernel; none shares code with it.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from selfplaydrive.maps.roadmap import RoadMap, SegmentType

# ---------------------------------------------------------------------------- physics (2.6)


def bicycle_step(
    x,
    y,
    heading,
    speed,
    length,
    accel,
    steer,
    hidden,
    dt=0.1,
    wheelbase_ratio=0.6,
    max_speed=40.0,
    gravity=9.81,
    friction=True,
):
    """One step of the (friction-limited) kinematic bicycle model for arrays of vehicles.

    Args:
        x, y, heading, speed, length: (n,) state [m], [rad], [m/s], [m].
        accel, steer: (n,) requested acceleration [m/s^2] and steering [rad].
        hidden: (n, 3) friction mu, accel gain, steer gain.

    Returns:
        dict of (n,) float64: x, y, heading, speed, a_long, a_lat.
    """
    x, y, h, v0, ln = (np.asarray(a, np.float64) for a in (x, y, heading, speed, length))
    acc = np.asarray(accel, np.float64) * hidden[:, 1]
    delta = np.asarray(steer, np.float64) * hidden[:, 2]
    lw = wheelbase_ratio * ln
    beta = np.arctan(0.5 * np.tan(delta))
    kappa = np.sin(beta) / (0.5 * lw)
    if friction:
        vreq = np.clip(v0 + acc * dt, 0.0, max_speed)
        total = np.hypot(acc, vreq**2 * kappa)
        limit = hidden[:, 0] * gravity
        scale = np.where(total > limit, limit / np.maximum(total, 1e-30), 1.0)
        acc, kappa = acc * scale, kappa * scale
        v1 = np.clip(v0 + acc * dt, 0.0, max_speed)
        lat_room = np.sqrt(np.maximum(limit**2 - acc**2, 0.0))
        over = v1**2 * np.abs(kappa) > lat_room
        kappa = np.where(over, np.sign(kappa) * lat_room / np.maximum(v1**2, 1e-30), kappa)
        beta = np.arcsin(np.clip(kappa * 0.5 * lw, -1, 1))
    v1 = np.clip(v0 + acc * dt, 0.0, max_speed)
    nx = x + v1 * np.cos(h + beta) * dt
    ny = y + v1 * np.sin(h + beta) * dt
    nh = np.angle(np.exp(1j * (h + v1 * kappa * dt)))
    return {"x": nx, "y": ny, "heading": nh, "speed": v1, "a_long": (v1 - v0) / dt, "a_lat": v1**2 * kappa}


# ------------------------------------------------------------------------- geometry (2.2)


def box_corners(x, y, heading, length, width) -> np.ndarray:
    """(4, 2) corners of an oriented box."""
    c, s = math.cos(heading), math.sin(heading)
    u, v = np.array([c, s]), np.array([-s, c])
    return np.array(
        [
            [x, y] + sx * 0.5 * length * u + sy * 0.5 * width * v
            for sx, sy in ((1, 1), (1, -1), (-1, -1), (-1, 1))
        ]
    )


def boxes_overlap(a: np.ndarray, b: np.ndarray) -> bool:
    """Separating-axis test on two (4, 2) corner arrays (projections of all corners)."""
    for poly in (a, b):
        for k in range(2):
            edge = poly[k + 1] - poly[k]
            axis = np.array([-edge[1], edge[0]])
            pa, pb = a @ axis, b @ axis
            if pa.max() < pb.min() or pb.max() < pa.min():
                return False
    return True


def segment_touches_box(p, q, corners: np.ndarray) -> bool:
    """Segment p-q intersects a convex box: an endpoint inside, or it crosses an edge."""

    def inside(pt):
        signs = []
        for k in range(4):
            e, r = corners[(k + 1) % 4] - corners[k], pt - corners[k]
            signs.append(e[0] * r[1] - e[1] * r[0])
        return all(s >= 0 for s in signs) or all(s <= 0 for s in signs)

    if inside(np.asarray(p)) or inside(np.asarray(q)):
        return True
    return any(_cross(p, q, corners[k], corners[(k + 1) % 4]) for k in range(4))


def _cross(a, b, c, d) -> bool:
    def orient(p, q, r):
        return (q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0])

    return orient(a, b, c) * orient(a, b, d) <= 0 and orient(c, d, a) * orient(c, d, b) <= 0


# ------------------------------------------------------------------ lane association (2.3)


def lane_association(road_map: RoadMap, x: float, y: float, heading: float, lane_radius: float = 5.0):
    """Nearest lane-centre segment within `lane_radius` [m], preferring those whose direction
    is within 90 deg of the heading. Returns (valid, s [m] + right, alpha [rad] + left)."""
    seg = road_map.segments
    lanes = np.flatnonzero(seg.type == int(SegmentType.LANE_CENTER))
    p = np.array([x, y])
    best = {True: (np.inf, -1), False: (np.inf, -1)}
    h = np.array([math.cos(heading), math.sin(heading)])
    for k in lanes:
        a, d, ln = seg.start[k].astype(np.float64), seg.dir[k].astype(np.float64), float(seg.length[k])
        t = np.clip((p - a) @ d, 0.0, ln)
        dist = np.linalg.norm(p - (a + t * d))
        if dist > lane_radius:
            continue
        if d @ h > 0 and dist < best[True][0]:
            best[True] = (dist, k)
        if dist < best[False][0]:
            best[False] = (dist, k)
    k = best[True][1] if best[True][1] >= 0 else best[False][1]
    if k < 0:
        return False, 0.0, 0.0
    a, d = seg.start[k].astype(np.float64), seg.dir[k].astype(np.float64)
    u = p - a
    s = u[0] * d[1] - u[1] * d[0]
    alpha = math.atan2(d[0] * h[1] - d[1] * h[0], d @ h)
    return True, s, alpha


# ---------------------------------------------------------------------- traffic lights (2.2)

_MASK64 = (1 << 64) - 1


def stream_bits(key: int, counter: int, n: int) -> tuple[list[int], int]:
    """The next `n` draws of a world's counter-based stream (rng.pxd) as 53-bit integers.

    Draw number c + 1 (after counter c) is the SplitMix64 finaliser of key + (c + 1) times the
    golden-ratio gamma; uniforms are bits / 2^53, integers in [0, m) are bits % m.

    Returns:
        The n integers in [0, 2^53) and the counter after them.
    """
    out = []
    for j in range(1, n + 1):
        z = (int(key) + (int(counter) + j) * 0x9E3779B97F4A7C15) & _MASK64
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & _MASK64
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _MASK64
        out.append((z ^ (z >> 31)) >> 11)
    return out, int(counter) + n


def light_step(state, time_left, key: int, counter: int, dt=0.1, light_min=0.5, light_max=10.0):
    """One step of the signal groups of one world whose lights are on (section 2.2).

    Each group's countdown loses dt; a group with at most dt / 2 left (the step nearest its
    scheduled change) moves to one of the 3 other states, uniformly, and draws a new duration
    U(light_min, light_max). Groups change in index order, two draws each (state, duration),
    from the world's stream. The countdown is float32 as in the simulator's buffers, so the
    change decision is the same one the kernel makes.

    Args:
        state: (G,) light states 0-3 (off, red, yellow, green).
        time_left: (G,) [s] until each group's next change.
        key, counter: The world's random stream and how many numbers it has drawn.

    Returns:
        (G,) int8 states, (G,) float64 time left [s], the counter after the step.
    """
    state = np.asarray(state, np.int64).copy()
    left = (np.asarray(time_left, np.float32) - np.float32(dt)).astype(np.float64)
    for g in np.flatnonzero(left <= np.float32(0.5 * np.float32(dt))):
        (bits_state, bits_time), counter = stream_bits(key, counter, 2)
        state[g] = (state[g] + 1 + bits_state % 3) % 4
        left[g] = light_min + (light_max - light_min) * bits_time / 2.0**53
    return state.astype(np.int8), left, counter


# --------------------------------------------------------------------------- rewards (2.3)


def reward_terms(
    events: dict[str, bool],
    v: float,
    coeffs: dict[str, float],
    lane: tuple[bool, float, float],
    params: Any = None,
) -> np.ndarray:
    """The eight terms of section 2.3 in the order of rewards.registry.TERM_NAMES, with the
    reward constants of `params` (a `SimParams`; None: the paper's, 0.25, 0.1, 0.05, ...)."""
    from selfplaydrive.sim.params import SimParams

    p = params if params is not None else SimParams()
    valid, s, alpha = lane
    t = np.zeros(8)
    t[0] = p.waypoint_reward if events.get("waypoint") else 0.0
    t[1] = -coeffs["collision"] * (1 + p.collision_speed_gain * v) if events.get("collision") else 0.0
    t[2] = -coeffs["offroad"] * (1 + p.collision_speed_gain * v) if events.get("offroad") else 0.0
    t[3] = -coeffs["red_light"] if events.get("red_light") else 0.0
    t[4] = -coeffs["comfort"] if events.get("comfort") else 0.0
    if valid:
        dev = abs(coeffs["center_bias"] - s)
        if abs(alpha) < math.radians(p.center_max_angle_deg):
            t[5] = coeffs["center"] * (-dev + p.center_bonus / math.exp(dev - p.center_bonus_offset))
        bonus = p.align_bonus * (1 - abs(alpha) / (math.pi / 2))
        t[6] = coeffs["align"] * (min(math.cos(alpha), 0.0) + bonus)
        if v >= p.velocity_min:
            t[7] = p.velocity_reward * max(math.cos(alpha), 0.0)
    return t


# ---------------------------------------------------------------------- observation (2.5)


def _ego_frame(dx, dy, c, s):
    return c * dx + s * dy, -s * dx + c * dy


def object_rows(
    b: dict[str, np.ndarray],
    dims,
    i: int,
    radius: float = 100.0,
    max_speed: float = 40.0,
    length_scale: float = 20.0,
    width_scale: float = 5.0,
) -> np.ndarray:
    """Rows (m, 9) of every body within `radius` of agent i (not only the nearest 63), from the
    env buffers; the kernel keeps the nearest max_objects of them, in any order."""
    w, A = divmod(i, dims.A)[0], dims.A
    x, y, h = float(b["x"][i]), float(b["y"][i]), float(b["heading"][i])
    c, s = math.cos(h), math.sin(h)
    bodies = []
    for j in range(w * A, (w + 1) * A):
        if j != i and (b["active"][j] or b["obstacle"][j]):
            hj = float(b["heading"][j])
            bodies.append(
                (
                    b["x"][j],
                    b["y"][j],
                    hj,
                    b["length"][j],
                    b["width"][j],
                    b["speed"][j] * math.cos(hj),
                    b["speed"][j] * math.sin(hj),
                )
            )
    for k in range(w * dims.S, (w + 1) * dims.S):
        if b["st_valid"][k]:
            bodies.append(
                (
                    b["st_x"][k],
                    b["st_y"][k],
                    math.atan2(b["st_sin"][k], b["st_cos"][k]),
                    b["st_len"][k],
                    b["st_wid"][k],
                    0.0,
                    0.0,
                )
            )
    for k in range(w * dims.P, (w + 1) * dims.P):
        if b["ped_valid"][k] and b["ped_here"][k]:
            bodies.append(
                (
                    b["ped_x"][k],
                    b["ped_y"][k],
                    math.atan2(b["ped_sin"][k], b["ped_cos"][k]),
                    b["ped_len"][k],
                    b["ped_wid"][k],
                    b["ped_vx"][k],
                    b["ped_vy"][k],
                )
            )
    rows = []
    for ox, oy, oh, ln, wd, vx, vy in bodies:
        dx, dy = float(ox) - x, float(oy) - y
        if dx * dx + dy * dy > radius * radius:
            continue
        ex, ey = _ego_frame(dx, dy, c, s)
        evx, evy = _ego_frame(vx, vy, c, s)
        rows.append(
            [
                1.0,
                ex / radius,
                ey / radius,
                math.cos(oh - h),
                math.sin(oh - h),
                ln / length_scale,
                wd / width_scale,
                evx / max_speed,
                evy / max_speed,
            ]
        )
    return np.clip(np.array(rows, dtype=np.float64).reshape(-1, 9), -1, 1)


def road_rows(
    road_map: RoadMap,
    light_state: np.ndarray,
    x: float,
    y: float,
    heading: float,
    radius: float = 100.0,
    max_road: int = 200,
    length_scale: float = 20.0,
) -> np.ndarray:
    """Rows (m, 8) of the nearest `max_road` segments within `radius` (brute force over the map)."""
    seg = road_map.segments
    d2 = np.sum((seg.mid.astype(np.float64) - (x, y)) ** 2, axis=1)
    idx = np.flatnonzero(d2 <= radius * radius)
    idx = idx[np.lexsort((idx, d2[idx]))][:max_road]
    c, s = math.cos(heading), math.sin(heading)
    rows = []
    for k in idx:
        ex, ey = _ego_frame(seg.mid[k, 0] - x, seg.mid[k, 1] - y, c, s)
        d = seg.dir[k].astype(np.float64)
        state = 0.0
        if seg.type[k] == int(SegmentType.TRAFFIC_LIGHT):
            g = road_map.light_group[seg.owner[k]]
            state = light_state[g] / 3.0 if g < len(light_state) else 0.0
        rows.append(
            [
                1.0,
                ex / radius,
                ey / radius,
                d[0] * c + d[1] * s,
                d[1] * c - d[0] * s,
                seg.length[k] / length_scale,
                seg.type[k] / 4.0,
                state,
            ]
        )
    return np.clip(np.array(rows, dtype=np.float64).reshape(-1, 8), -1, 1)


def ego_row(
    b: dict[str, np.ndarray], dims, i: int, coeff_scale, max_speed: float = 40.0, wp_scale: float = 200.0
) -> np.ndarray:
    """The 19 ego features of agent i (obs/layout.py EGO_FEATURES)."""
    x, y, h = float(b["x"][i]), float(b["y"][i]), float(b["heading"][i])
    c, s = math.cos(h), math.sin(h)
    k, n = int(b["wp_idx"][i]), int(b["num_wp"][i])
    wp0 = wp1 = (0.0, 0.0)
    if k < n:
        p0, p1 = b["waypoints"][i, k], b["waypoints"][i, min(k + 1, n - 1)]
        wp0 = _ego_frame(p0[0] - x, p0[1] - y, c, s)
        wp1 = _ego_frame(p1[0] - x, p1[1] - y, c, s)
    row = [
        b["width"][i] / 5.0,
        b["length"][i] / 20.0,
        b["speed"][i] / max_speed,
        wp0[0] / wp_scale,
        wp0[1] / wp_scale,
        wp1[0] / wp_scale,
        wp1[1] / wp_scale,
        (n - k) / dims.K,
        b["lane_s"][i] / 5.0,
        b["lane_alpha"][i] / math.pi,
        float(b["lane_valid"][i]),
    ]
    row += list(b["coeffs"][i] / np.asarray(coeff_scale))
    return np.clip(np.array(row, dtype=np.float64), -1, 1)
