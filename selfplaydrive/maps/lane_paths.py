"""Polyline and lane-chain helpers of the rule-adherence suites (paper section 5.3) and the
turn-lane training starts (`scenario/turn_sites.py`).

Everything here is float64 NumPy in the map's local frame [m]. A *path* is an (n, 2) polyline;
its arc length runs from 0 at the first point. Lateral offsets are signed, positive to the
right of the direction of travel (the convention of the simulator's `lane_s`, docs/world.md).
"""

from __future__ import annotations

import numpy as np

from selfplaydrive.maps.roadmap import LaneKind, RoadMap


def cumlen(path: np.ndarray) -> np.ndarray:
    """(n,) arc length [m] at each point of an (n, 2) path."""
    d = np.hypot(*np.diff(path, axis=0).T) if len(path) > 1 else np.zeros(0)
    return np.concatenate([[0.0], np.cumsum(d)])


def point_at(path: np.ndarray, s: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    """Points and headings at arc lengths `s` [m] (clipped to the path).

    Returns:
        xy (..., 2) float64 [m] and heading (...,) float64 [rad].
    """
    cum = cumlen(path)
    s = np.clip(np.asarray(s, dtype=np.float64), 0.0, cum[-1])
    k = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(path) - 2)
    seg = path[k + 1] - path[k]
    seg_len = np.maximum(cum[k + 1] - cum[k], 1e-12)
    f = ((s - cum[k]) / seg_len)[..., None]
    return path[k] + f * seg, np.arctan2(seg[..., 1], seg[..., 0])


def project(path: np.ndarray, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nearest point of `path` to each of `pts` (m, 2).

    Returns:
        s (m,) arc length of the foot point [m], lateral (m,) signed offset (+ right) [m],
        dist (m,) unsigned distance [m].
    """
    pts = np.asarray(pts, dtype=np.float64).reshape(-1, 2)
    a, b = path[:-1], path[1:]
    d = b - a
    dd = np.maximum(np.sum(d * d, axis=1), 1e-12)
    w = pts[:, None, :] - a[None, :, :]
    t = np.clip(np.sum(w * d[None], axis=2) / dd[None], 0.0, 1.0)
    gap = w - t[..., None] * d[None]
    dist2 = np.sum(gap * gap, axis=2)
    k = np.argmin(dist2, axis=1)
    r = np.arange(len(pts))
    cum = cumlen(path)
    s = cum[k] + t[r, k] * np.sqrt(dd[k])
    cross = d[k, 0] * w[r, k, 1] - d[k, 1] * w[r, k, 0]  # > 0: left of the segment
    dist = np.sqrt(dist2[r, k])
    return s, np.where(cross > 0, -dist, dist), dist


def track(
    path: np.ndarray, pts: np.ndarray, window: tuple[float, float] = (-5.0, 25.0)
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Project consecutive positions (a trajectory) onto `path`, each one searched only within
    `window` [m] of the previous frame's arc length, so a path that passes near itself (a
    roundabout) is followed, not jumped. The first frame is searched over the whole path.

    Returns:
        s (m,), lateral (m,) (+ right), dist (m,), as `project`.
    """
    pts = np.asarray(pts, dtype=np.float64).reshape(-1, 2)
    s, lat, dist = (np.zeros(len(pts)) for _ in range(3))
    total = cumlen(path)[-1]
    prev = None
    for i, p in enumerate(pts):
        if prev is None:
            piece, base = path, 0.0
        else:
            lo, hi = max(prev + window[0], 0.0), min(prev + window[1], total)
            piece, base = cut(path, lo, max(hi, lo + 1e-3)), lo
        a, b, c = project(piece, p[None])
        s[i], lat[i], dist[i] = base + a[0], b[0], c[0]
        prev = s[i]
    return s, lat, dist


def segment_hits(line: np.ndarray, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where polyline `line` crosses segment a-b.

    Returns:
        points (h, 2) [m] and the heading [rad] of the crossing piece of `line` at each.
    """
    p, r = line[:-1], np.diff(line, axis=0)
    q, d = np.asarray(a, np.float64), np.asarray(b, np.float64) - np.asarray(a, np.float64)
    den = r[:, 0] * d[1] - r[:, 1] * d[0]
    ok = np.abs(den) > 1e-12
    den = np.where(ok, den, 1.0)
    w = q - p
    t = (w[:, 0] * d[1] - w[:, 1] * d[0]) / den  # along the polyline piece
    u = (w[:, 0] * r[:, 1] - w[:, 1] * r[:, 0]) / den  # along a-b
    hit = ok & (t >= 0) & (t < 1) & (u >= 0) & (u <= 1)
    pts = p[hit] + t[hit, None] * r[hit]
    return pts, np.arctan2(r[hit, 1], r[hit, 0])


def lane_linestrings(geo: LaneGeometry, lanes: np.ndarray) -> np.ndarray:
    """shapely LineStrings of the centerlines of `lanes`, built in one call."""
    import shapely

    lines = [geo.line(i) for i in lanes]
    idx = np.repeat(np.arange(len(lines)), [len(x) for x in lines])
    return shapely.linestrings(np.concatenate(lines), indices=idx)


def join(parts: list[np.ndarray]) -> np.ndarray:
    """Concatenate polylines, dropping a repeated joint point."""
    out = [np.asarray(parts[0], dtype=np.float64)]
    for p in parts[1:]:
        p = np.asarray(p, dtype=np.float64)
        if np.hypot(*(p[0] - out[-1][-1])) < 1e-3:
            p = p[1:]
        if len(p):
            out.append(p)
    return np.concatenate(out)


def cut(path: np.ndarray, s0: float, s1: float) -> np.ndarray:
    """The piece of `path` between arc lengths s0 < s1 [m] (end points interpolated)."""
    cum = cumlen(path)
    inner = path[(cum > s0) & (cum < s1)]
    a, _ = point_at(path, s0)
    b, _ = point_at(path, s1)
    return np.concatenate([a[None], inner, b[None]])


def wrap(a: np.ndarray | float) -> np.ndarray:
    """Angle(s) wrapped to (-pi, pi]."""
    return np.angle(np.exp(1j * np.asarray(a, dtype=np.float64)))


class LaneGeometry:
    """Per-lane centerlines (float64), lengths and end headings of one `RoadMap`.

    Args:
        road_map: The map.
    """

    def __init__(self, road_map: RoadMap) -> None:
        self.road_map = road_map
        lanes = road_map.lanes
        self.lanes = lanes
        self.length = lanes.centerlines.lengths()
        self.vehicle = lanes.kind != LaneKind.BICYCLE
        pts = lanes.centerlines
        self._lines = [pts[i].astype(np.float64) for i in range(len(lanes))]
        self.start_heading = np.array([_heading(p, 0) for p in self._lines])
        self.end_heading = np.array([_heading(p, -1) for p in self._lines])

    def line(self, lane: int) -> np.ndarray:
        """(n, 2) float64 centerline of `lane` [m]."""
        return self._lines[int(lane)]

    def turn(self, lane: int) -> float:
        """Heading change along `lane` [rad], + left."""
        return float(wrap(self.end_heading[lane] - self.start_heading[lane]))

    def path(self, chain: list[int]) -> np.ndarray:
        """Centerline of consecutive lanes as one polyline."""
        return join([self.line(i) for i in chain])

    def straightest_pred(self, lane: int, allow=None) -> int:
        """The vehicle predecessor continuing `lane` most straight, or -1 (`allow(i)` filters)."""
        cands = [int(p) for p in self.lanes.predecessors(lane) if self.vehicle[p]]
        if allow is not None:
            cands = [p for p in cands if allow(p)]
        if not cands:
            return -1
        dev = [abs(float(wrap(self.start_heading[lane] - self.end_heading[p]))) for p in cands]
        return cands[int(np.argmin(dev))]

    def straightest_succ(self, lane: int, allow=None) -> int:
        """The vehicle successor continuing `lane` most straight, or -1."""
        cands = [int(q) for q in self.lanes.successors(lane) if self.vehicle[q]]
        if allow is not None:
            cands = [q for q in cands if allow(q)]
        if not cands:
            return -1
        dev = [abs(float(wrap(self.start_heading[q] - self.end_heading[lane]))) for q in cands]
        return cands[int(np.argmin(dev))]

    def lane_at(self, chain: list[int], arc: float) -> int:
        """Lane of consecutive lanes `chain` that covers arc length `arc` [m] of their path."""
        ends = np.cumsum([self.length[i] for i in chain])
        return int(chain[min(int(np.searchsorted(ends, arc)), len(chain) - 1)])

    def chain_back(self, lane: int, length: float, allow=None) -> list[int]:
        """Lanes ending in `lane` (last), walked back over the straightest predecessors until
        they cover `length` [m] before the start of `lane` or run out (`allow` filters)."""
        chain, got, seen = [int(lane)], 0.0, {int(lane)}
        while got < length:
            p = self.straightest_pred(chain[0], allow)
            if p < 0 or p in seen:
                break
            chain.insert(0, p)
            seen.add(p)
            got += self.length[p]
        return chain

    def chain_forward(self, lane: int, length: float, allow=None) -> list[int]:
        """Lanes starting with `lane`, walked forward over the straightest successors until
        they cover `length` [m] after the end of `lane` or run out."""
        chain, got, seen = [int(lane)], 0.0, {int(lane)}
        while got < length:
            q = self.straightest_succ(chain[-1], allow)
            if q < 0 or q in seen:
                break
            chain.append(q)
            seen.add(q)
            got += self.length[q]
        return chain


def _heading(p: np.ndarray, end: int) -> float:
    d = p[1] - p[0] if end == 0 else p[-1] - p[-2]
    return float(np.arctan2(d[1], d[0]))


def boxes_overlap(c1, h1, l1, w1, c2, h2, l2, w2) -> bool:
    """Separating-axis test of two oriented boxes (centre [m], heading [rad], length, width [m])."""
    corners = []
    for c, h, ln, wd in ((c1, h1, l1, w1), (c2, h2, l2, w2)):
        u = np.array([np.cos(h), np.sin(h)])
        v = np.array([-u[1], u[0]])
        corners.append(np.array([c + sx * ln / 2 * u + sy * wd / 2 * v for sx in (-1, 1) for sy in (-1, 1)]))
    for h in (h1, h2):
        for axis in (np.array([np.cos(h), np.sin(h)]), np.array([-np.sin(h), np.cos(h)])):
            p1, p2 = corners[0] @ axis, corners[1] @ axis
            if p1.max() < p2.min() or p2.max() < p1.min():
                return False
    return True
