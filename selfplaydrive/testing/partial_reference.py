"""Plain NumPy reference of the partial-observability encoder (_sim/partial.pyx; issue #15
item 5; docs/observation.md "Partial observability"), for tests: the same rules, written for
clarity (explicit loops over objects, float64), and the same random draws (the counter-based
stream of _sim/rng.pxd, drawn through `selfplaydrive._sim.rng.uniform`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from selfplaydrive.obs.layout import OBJECT_FEATURES

OBJ_DIM = len(OBJECT_FEATURES)
ROW_DRAWS = 8  # draws reserved per object row (_sim/partial.pyx)
FP_BASE = 8 * 4096  # first counter of the false positives, after the rows'


def row_counter(step: int, slot: int, row: int) -> int:
    """First counter of object row `row` of agent `slot` at episode step `step`."""
    return ((step << 40) + (slot << 24) + ROW_DRAWS * row) % 2**64


def _uniforms(key: int, counter: int, n: int) -> np.ndarray:
    from selfplaydrive._sim.rng import uniform

    return uniform(key, counter, n)[0]


def angular_extent(row: np.ndarray, scales: Mapping[str, float]) -> tuple[float, float, float] | None:
    """(lo, hi, centre distance) of one object row seen from the ego's centre: the corner
    angles minus the centre's angle; None when the box contains the ego's centre."""
    x, y = row[1] * scales["pos"], row[2] * scales["pos"]
    c, s = float(row[3]), float(row[4])
    hl, hw = 0.5 * row[5] * scales["length"], 0.5 * row[6] * scales["width"]
    lx, ly = -(c * x + s * y), -(-s * x + c * y)
    if abs(lx) <= hl and abs(ly) <= hw:
        return None
    angles = []
    for sl in (-1, 1):
        for sw in (-1, 1):
            qx = x + sl * hl * c - sw * hw * s
            qy = y + sl * hl * s + sw * hw * c
            angles.append(math.atan2(x * qy - y * qx, x * qx + y * qy))
    return min(angles), max(angles), math.hypot(x, y)


def _centre_angle(row: np.ndarray, scales: Mapping[str, float]) -> float:
    return math.atan2(row[2] * scales["pos"], row[1] * scales["pos"])


def visible_fractions(rows: np.ndarray, scales: Mapping[str, float]) -> np.ndarray:
    """Visible share of each row's angular extent: the part not covered by the extents of
    bodies with a smaller centre distance (shadow casting)."""
    n = len(rows)
    ext = [angular_extent(r, scales) for r in rows]
    out = np.ones(n)
    for j in range(n):
        ej = ext[j]
        if ej is None or ej[1] <= ej[0]:
            continue
        lo, hi, dj = ej
        pieces = []
        for i in range(n):
            ei = ext[i]
            if i == j or ei is None or not ei[2] < dj:
                continue
            # angle of i's centre measured from j's centre direction, in (-pi, pi]
            delta = _centre_angle(rows[i], scales) - _centre_angle(rows[j], scales)
            if delta > math.pi:
                delta -= 2 * math.pi
            elif delta <= -math.pi:
                delta += 2 * math.pi
            for shift in (-2 * math.pi, 0.0, 2 * math.pi):
                a, b = max(delta + ei[0] + shift, lo), min(delta + ei[1] + shift, hi)
                if b > a:
                    pieces.append((a, b))
        if not pieces:
            continue
        pieces.sort()
        covered, (start, end) = 0.0, pieces[0]
        for a, b in pieces[1:]:
            if a > end:  # a gap: close the covered run
                covered += end - start
                start, end = a, b
            else:
                end = max(end, b)
        covered += end - start
        out[j] = (hi - lo - covered) / (hi - lo)
    return out


def postprocess(
    rows: np.ndarray,
    n: int,
    params: Mapping[str, Any],
    key: int,
    step: int,
    slot: int,
    scales: Mapping[str, float],
) -> tuple[np.ndarray, int]:
    """The encoder's effects on one agent's object rows ((max_obj, 9), `n` of them written):
    occlusion, then misses, noise, false positives. Returns (new rows, new count).

    Args:
        rows: The paper encoder's object rows of the agent.
        n: Rows written (the rest are zero).
        params: The encoder's parameters (`PartialObsEncoder.params`).
        key: The encoder's stream of the world (`_sim.partial.stream_key(world_key, salt)`).
        step: The world's episode step (`state.step[w]`).
        slot: The agent's slot in its world.
        scales: "pos" (the radius), "length", "width", "speed" (max_speed).
    """
    p = params
    rows = np.asarray(rows, dtype=np.float64)
    max_obj = len(rows)
    keep = np.ones(n, dtype=bool)
    if p["occlusion"]:
        keep = visible_fractions(rows[:n], scales) >= np.float32(p["visible_fraction"])
    out = np.zeros_like(rows)
    m = 0
    noisy = p["pos_std"] > 0 or p["heading_std"] > 0 or p["speed_std"] > 0
    for k in range(n):
        if not keep[k]:
            continue
        u = _uniforms(key, row_counter(step, slot, k), 5)
        if p["p_miss"] > 0 and u[0] < np.float32(p["p_miss"]):
            continue
        r = rows[k].copy()
        if noisy:
            z = []
            for u1, u2 in ((u[1], u[2]), (u[3], u[4])):
                rad = math.sqrt(-2.0 * math.log(1.0 - u1))
                z += [rad * math.cos(2 * math.pi * u2), rad * math.sin(2 * math.pi * u2)]
            r = _noise(r, p, z, scales)
        out[m] = r
        m += 1
    if p["fp_rate"] > 0 and m < max_obj:
        ctr = row_counter(step, slot, 0) + FP_BASE
        u0 = _uniforms(key, ctr, 1)[0]
        count, pk = 0, math.exp(-float(np.float32(p["fp_rate"])))
        cdf = pk
        while u0 >= cdf and count < max_obj - m:
            count += 1
            pk *= float(np.float32(p["fp_rate"])) / count
            cdf += pk
            if pk < 1e-300:
                break
        draws = _uniforms(key, ctr + 1, 3 * count).reshape(count, 3)
        for ur, ua, uh in draws:
            rad = scales["pos"] * math.sqrt(ur)
            ang, th = 2 * math.pi * ua, 2 * math.pi * uh - math.pi
            out[m] = [
                1.0,
                np.clip(rad * math.cos(ang) / scales["pos"], -1, 1),
                np.clip(rad * math.sin(ang) / scales["pos"], -1, 1),
                math.cos(th),
                math.sin(th),
                min(float(np.float32(p["fp_length"])) / scales["length"], 1.0),
                min(float(np.float32(p["fp_width"])) / scales["width"], 1.0),
                0.0,
                0.0,
            ]
            m += 1
    return out.astype(np.float32), m


def _noise(r: np.ndarray, p: Mapping[str, Any], z: list[float], scales: Mapping[str, float]) -> np.ndarray:
    f = {k: float(np.float32(p[k])) for k in ("pos_std", "heading_std", "speed_std")}
    c, s = float(r[3]), float(r[4])
    if f["pos_std"] > 0:
        r[1] = np.clip(r[1] + z[0] * f["pos_std"] / scales["pos"], -1, 1)
        r[2] = np.clip(r[2] + z[1] * f["pos_std"] / scales["pos"], -1, 1)
    if f["heading_std"] > 0:
        th = z[2] * f["heading_std"]
        c, s = c * math.cos(th) - s * math.sin(th), s * math.cos(th) + c * math.sin(th)
        r[3], r[4] = np.clip(c, -1, 1), np.clip(s, -1, 1)
    if f["speed_std"] > 0:
        vx, vy = r[7] * scales["speed"], r[8] * scales["speed"]
        sp = math.hypot(vx, vy)
        sp2 = max(sp + z[3] * f["speed_std"], 0.0)
        if sp > 1e-6:
            vx, vy = vx * sp2 / sp, vy * sp2 / sp
        else:
            vx, vy = c * sp2, s * sp2
        r[7], r[8] = np.clip(vx / scales["speed"], -1, 1), np.clip(vy / scales["speed"], -1, 1)
    return r
