"""NumPy references of the rule terms (issue #15; kernels in selfplaydrive/_sim/rules.pyx).

Plain loops over every record of a world's map (no grid), in float32 with the kernels' order of
operations, so a kernel and its reference agree bit for bit on random states
(tests/rewards/test_rules.py). Each function takes the env state after a step (`VecEnv.state`
or any object with the same arrays), the env's maps and the term's parameters, and returns the
(N,) term values of the active slots (0 elsewhere); `stop_sign` and `turn_lane` also take their
`term_state` column before the step and return the column after it.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from selfplaydrive.maps.roadmap import RoadMap
from selfplaydrive.rewards.rules import (
    TURN_ENTRY,
    crosswalk_records,
    lane_records,
    stop_records,
    turn_records,
    zone_records,
)

F = np.float32
RED = 1  # SD_LIGHT_RED
HALF_PI = 1.5707963267948966
_TABLES: dict[tuple[int, str, tuple[float, ...]], tuple[RoadMap, np.ndarray]] = {}


def _table(road_map: RoadMap, kind: str, *extra: float) -> np.ndarray:
    """The map's float32 records of one term (as packed), built once per map and `extra`
    (the term's table parameters)."""
    key = (id(road_map), kind, tuple(float(e) for e in extra))
    if key not in _TABLES or _TABLES[key][0] is not road_map:
        build = {
            "zone": zone_records,
            "stop": stop_records,
            "cross": crosswalk_records,
            "lane": lane_records,
            "turn": turn_records,
        }
        _TABLES[key] = (road_map, build[kind](road_map, *extra)[0].astype(F))
    return _TABLES[key][1]


def _agents(st: Any) -> tuple[int, int]:
    W = len(st.map_id)
    return W, len(st.x) // W


def red_intersection(st: Any, maps: Sequence[RoadMap], params: Sequence[float]) -> np.ndarray:
    """-1 where the centre entered a red controlled area this step (rules.pyx)."""
    L, R, D, cmax = (F(p) for p in params)
    W, A = _agents(st)
    G = len(st.light_state) // W
    tables = [_table(m, "zone") for m in maps]
    out = np.zeros(W * A, F)
    for w in range(W):
        z = tables[int(st.map_id[w])]
        if not st.lights_on[w] or len(z) == 0:
            continue
        g = z[:, 4].astype(np.int64)
        red = (g >= 0) & (g < G) & (st.light_state[w * G + np.clip(g, 0, G - 1)] == RED)
        for i in range(w * A, (w + 1) * A):
            if not st.active[i]:
                continue
            px, py, qx, qy = st.px[i], st.py[i], st.x[i], st.y[i]
            ok = red & (st.hcos[i] * z[:, 2] + st.hsin[i] * z[:, 3] >= cmax)
            ok &= _enters(z, px, py, qx, qy, L, R, D)
            for j in np.flatnonzero(ok):
                same = g == g[j]
                if not _inside(z[same], px, py, L, R, D).any():
                    out[i] = F(-1.0)
                    break
    return out


def _inside(z: np.ndarray, x: F, y: F, L: F, R: F, D: F) -> np.ndarray:
    dx, dy = x - z[:, 0], y - z[:, 1]
    al, lt = dx * z[:, 2] + dy * z[:, 3], dy * z[:, 2] - dx * z[:, 3]
    return (al >= 0) & (al <= D) & (lt >= -R) & (lt <= L)


def _enters(z: np.ndarray, px: F, py: F, qx: F, qy: F, L: F, R: F, D: F) -> np.ndarray:
    """Per zone: p outside and the segment p -> q meets the zone (Liang-Barsky)."""
    dx, dy = px - z[:, 0], py - z[:, 1]
    ap, bp = dx * z[:, 2] + dy * z[:, 3], dy * z[:, 2] - dx * z[:, 3]
    ex, ey = qx - z[:, 0], qy - z[:, 1]
    da, db = (ex * z[:, 2] + ey * z[:, 3]) - ap, (ey * z[:, 2] - ex * z[:, 3]) - bp
    lo, hi = np.zeros(len(z), F), np.ones(len(z), F)
    ok = ~((ap >= 0) & (ap <= D) & (bp >= -R) & (bp <= L))
    for p, q in ((-da, ap), (da, D - ap), (-db, bp + R), (db, L - bp)):
        zero = p == 0
        ok &= ~zero | (q >= 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            r = q / np.where(zero, F(1.0), p)
        lo = np.where(~zero & (p < 0), np.maximum(lo, r), lo)
        hi = np.where(~zero & (p > 0), np.minimum(hi, r), hi)
    return ok & (lo <= hi)


def stop_sign(
    st: Any, maps: Sequence[RoadMap], params: Sequence[float], state: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(-1 where a STOP line was crossed without a stop, the state column after the step)."""
    vs, dist = F(params[0]), F(params[1])
    W, A = _agents(st)
    tables = [_table(m, "stop") for m in maps]
    out, new = np.zeros(W * A, F), np.array(state, F).copy()
    for w in range(W):
        s6 = tables[int(st.map_id[w])]
        for i in range(w * A, (w + 1) * A):
            if not st.active[i]:
                continue
            s = F(state[i])
            crossed = bool((_crossing(s6, st.px[i], st.py[i], st.x[i], st.y[i]) > 0).any())
            # the kernel's `s - 1.0 <= dist + 0.5 * length` is evaluated in double
            ok = st.speed[i] <= vs or (s > 0 and float(s) - 1.0 <= float(dist) + 0.5 * float(st.length[i]))
            out[i] = F(-1.0) if crossed and not ok else F(0.0)
            if st.speed[i] <= vs:
                new[i] = F(1.0)
            elif s > 0:
                dx, dy = st.x[i] - st.px[i], st.y[i] - st.py[i]
                new[i] = s + np.sqrt(dx * dx + dy * dy, dtype=F)
    return out, new


def crosswalk_yield(st: Any, maps: Sequence[RoadMap], params: Sequence[float]) -> np.ndarray:
    """-1 where the centre entered a crosswalk a pedestrian is on or about to step on."""
    ahead, margin = F(params[0]), F(params[1])
    W, A = _agents(st)
    P = len(st.ped_x) // W
    tables = [_table(m, "cross") for m in maps]
    out = np.zeros(W * A, F)
    for w in range(W):
        peds = [j for j in range(w * P, (w + 1) * P) if st.ped_valid[j] and st.ped_here[j]]
        for i in range(w * A, (w + 1) * A):
            if not st.active[i]:
                continue
            polys = tables[int(st.map_id[w])]
            p, q = (st.px[i], st.py[i]), (st.x[i], st.y[i])
            # polygons whose box the move's box misses cannot be entered (the kernel's grid
            # skips them likewise)
            meet = (polys[:, 1] <= max(p[0], q[0])) & (polys[:, 3] >= min(p[0], q[0]))
            meet &= (polys[:, 2] <= max(p[1], q[1])) & (polys[:, 4] >= min(p[1], q[1]))
            for poly in polys[meet]:
                v = poly[5 : 5 + 2 * int(poly[0])].reshape(-1, 2)
                if _in_polygon(v, *p) or not (_in_polygon(v, *q) or _crosses_outline(v, p, q)):
                    continue
                if any(_near(v, st, j, ahead, margin) for j in peds):
                    out[i] = F(-1.0)
                    break
    return out


def _in_polygon(v: np.ndarray, x: F, y: F) -> bool:
    inside = False
    for k in range(len(v)):
        (x0, y0), (x1, y1) = v[k], v[(k + 1) % len(v)]
        if (y0 > y) != (y1 > y) and x < x0 + (y - y0) * (x1 - x0) / (y1 - y0):
            inside = not inside
    return inside


def _orient(a: Any, b: Any, c: Any) -> F:
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])


def _crosses_outline(v: np.ndarray, p: Any, q: Any) -> bool:
    for k in range(len(v)):
        a, b = v[k], v[(k + 1) % len(v)]
        if (_orient(p, q, a) > 0) != (_orient(p, q, b) > 0) and (_orient(a, b, p) > 0) != (
            _orient(a, b, q) > 0
        ):
            return True
    return False


def _near(v: np.ndarray, st: Any, j: int, ahead: F, margin: F) -> bool:
    for x, y in (
        (st.ped_x[j], st.ped_y[j]),
        (st.ped_x[j] + st.ped_vx[j] * ahead, st.ped_y[j] + st.ped_vy[j] * ahead),
    ):
        if _in_polygon(v, x, y):
            return True
        e = np.roll(v, -1, axis=0) - v
        t = np.clip(
            ((x - v[:, 0]) * e[:, 0] + (y - v[:, 1]) * e[:, 1]) / (e[:, 0] * e[:, 0] + e[:, 1] * e[:, 1]),
            0,
            1,
        )
        dx, dy = x - (v[:, 0] + t * e[:, 0]), y - (v[:, 1] + t * e[:, 1])
        if (dx * dx + dy * dy).min() <= margin * margin:
            return True
    return False


def wrong_way(st: Any, maps: Sequence[RoadMap], params: Sequence[float], dt: float) -> np.ndarray:
    """-dt where the agent drives against every lane its centre lies on (not when its lane
    association puts it within the map's narrowest half lane width of a lane going its way)."""
    vmin = F(params[0])
    W, A = _agents(st)
    tables = [_table(m, "lane") for m in maps]
    out = np.zeros(W * A, F)
    for w in range(W):
        s = tables[int(st.map_id[w])]
        narrow = s[:, 5].min() if len(s) else F(0.0)
        for i in range(w * A, (w + 1) * A):
            if not st.active[i] or st.speed[i] <= vmin:
                continue
            # on the associated lane going its way (the kernel's shortcut, same result)
            if st.lane_valid[i] and abs(float(st.lane_alpha[i])) < HALF_PI and abs(st.lane_s[i]) <= narrow:
                continue
            dx, dy = st.x[i] - s[:, 0], st.y[i] - s[:, 1]
            t = dx * s[:, 2] + dy * s[:, 3]
            on = (t >= 0) & (t <= s[:, 4]) & (np.abs(dx * s[:, 3] - dy * s[:, 2]) <= s[:, 5])
            along = st.hcos[i] * s[:, 2] + st.hsin[i] * s[:, 3] >= 0
            if (on & ~along).any() and not (on & along).any():
                out[i] = -F(dt)
    return out


def turn_lane(
    st: Any, maps: Sequence[RoadMap], params: Sequence[float], state: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(-1 where the centre crossed junction lanes the entry lane on record does not lead to,
    the state column after the step: 0 or 1 + the entry lane)."""
    cmax = F(params[0])
    W, A = _agents(st)
    tables = [_table(m, "turn", params[1]) for m in maps]
    out, new = np.zeros(W * A, F), np.array(state, F).copy()
    for w in range(W):
        g = tables[int(st.map_id[w])]
        entry, check = g[g[:, 6] == F(TURN_ENTRY)], g[g[:, 6] != F(TURN_ENTRY)]
        for i in range(w * A, (w + 1) * A):
            if not st.active[i]:
                continue
            side = _crossing(entry, st.px[i], st.py[i], st.x[i], st.y[i])
            crossed_entries = entry[side > 0, 7]
            s = int(crossed_entries.min()) + 1 if len(crossed_entries) else int(state[i])
            along = st.hcos[i] * check[:, 4] + st.hsin[i] * check[:, 5] >= cmax
            hit = check[along & (_crossing(check, st.px[i], st.py[i], st.x[i], st.y[i]) != 0)]
            if s > 0 and len(hit):
                legal = (hit[:, 9:] == F(s - 1)) & (np.arange(hit.shape[1] - 9) < hit[:, 8:9])
                out[i] = F(0.0) if legal.any() else F(-1.0)
                s = 0
            new[i] = F(s)
    return out, new


def _crossing(g: np.ndarray, px: F, py: F, qx: F, qy: F) -> np.ndarray:
    """Per line segment or gate (ax, ay, ex, ey, nx, ny, ..): +1 crossed along n, -1 against
    it, 0 missed (rules.pyx `crossing`)."""
    sp = (px - g[:, 0]) * g[:, 4] + (py - g[:, 1]) * g[:, 5]
    sq = (qx - g[:, 0]) * g[:, 4] + (qy - g[:, 1]) * g[:, 5]
    with np.errstate(divide="ignore", invalid="ignore"):
        f = sp / (sp - sq)
        cx, cy = px + f * (qx - px), py + f * (qy - py)
        t = ((cx - g[:, 0]) * g[:, 2] + (cy - g[:, 1]) * g[:, 3]) / (g[:, 2] * g[:, 2] + g[:, 3] * g[:, 3])
    hit = ((sp < 0) != (sq < 0)) & (t >= 0) & (t <= 1)
    return np.where(hit, np.where(sp < 0, 1, -1), 0)
