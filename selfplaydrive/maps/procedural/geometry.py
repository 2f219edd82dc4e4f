"""Planar curve helpers for the town generator: arc-length paths, offsets, Beziers, arcs.

All points are (n, 2) float64 [m]; angles [rad], counter-clockwise from +x.
"""

from __future__ import annotations

import math

import numpy as np

CURVE_STEP = 2.0  # [m] point spacing on junction curves (connectors, ring, curbs)


def unit(v: np.ndarray) -> np.ndarray:
    """Unit vector(s) along the last axis (zero vectors stay zero)."""
    n = np.sqrt(np.sum(v * v, axis=-1, keepdims=True))
    return v / np.maximum(n, 1e-12)


def right_normal(t: np.ndarray) -> np.ndarray:
    """Normal(s) pointing to the right of direction(s) `t` (right-hand traffic side)."""
    return np.stack([t[..., 1], -t[..., 0]], axis=-1)


def wrap_angle(a: float) -> float:
    """Angle wrapped to (-pi, pi] [rad]."""
    return math.atan2(math.sin(a), math.cos(a))


class Path:
    """A polyline parametrised by arc length s [m], with smooth vertex tangents.

    Args:
        points: (n, 2) float64, n >= 2, consecutive points distinct.
    """

    def __init__(self, points: np.ndarray) -> None:
        self.points = np.asarray(points, dtype=np.float64)
        seg = np.diff(self.points, axis=0)
        self.s = np.concatenate([[0.0], np.cumsum(np.hypot(seg[:, 0], seg[:, 1]))])
        seg_t = unit(seg)
        # vertex tangents: mean of the adjacent segment directions, so offsets stay smooth
        vt = np.concatenate([seg_t[:1], seg_t[:-1] + seg_t[1:], seg_t[-1:]])
        self.vertex_tangent = unit(vt)

    @property
    def length(self) -> float:
        """Total arc length [m]."""
        return float(self.s[-1])

    def reversed(self) -> Path:
        """The same curve travelled the other way."""
        return Path(self.points[::-1].copy())

    def frame(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Points and unit tangents at arc lengths `s` (clipped to [0, length]).

        Returns:
            (points (k, 2), tangents (k, 2)).
        """
        s = np.clip(np.asarray(s, dtype=np.float64), 0.0, self.length)
        i = np.clip(np.searchsorted(self.s, s, side="right") - 1, 0, len(self.s) - 2)
        span = self.s[i + 1] - self.s[i]
        f = ((s - self.s[i]) / np.maximum(span, 1e-12))[:, None]
        pts = self.points[i] * (1.0 - f) + self.points[i + 1] * f
        tan = unit(self.vertex_tangent[i] * (1.0 - f) + self.vertex_tangent[i + 1] * f)
        return pts, tan

    def sample_s(self, s0: float, s1: float, extra: tuple[float, ...] = ()) -> np.ndarray:
        """Arc lengths from s0 to s1 at the path's own vertices and at `extra` positions.

        A straight path gives just its two ends (compile_map cuts long segments later); curved
        paths are already sampled densely by their vertices.
        """
        inner = self.s[(self.s > s0 + 1e-6) & (self.s < s1 - 1e-6)]
        ex = np.array([e for e in extra if s0 + 1e-6 < e < s1 - 1e-6])
        s = np.unique(np.concatenate([[s0, s1], inner, ex]))
        keep = np.concatenate([[True], np.diff(s) > 0.05])  # drop near-duplicates
        keep[-1] = True
        s = s[keep]
        if len(s) > 2 and s[-1] - s[-2] <= 0.05:
            s = np.delete(s, -2)
        return s

    def offset(self, s: np.ndarray, right: np.ndarray | float) -> np.ndarray:
        """Points at arc lengths `s`, moved `right` [m] to the right of the direction of travel."""
        p, t = self.frame(s)
        return p + np.asarray(right, dtype=np.float64).reshape(-1, 1) * right_normal(t)


def smoothstep(x: np.ndarray) -> np.ndarray:
    """0 for x <= 0, 1 for x >= 1, C1-smooth in between."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def cubic_bezier(p0: np.ndarray, p1: np.ndarray, p2: np.ndarray, p3: np.ndarray, n: int) -> np.ndarray:
    """n points on the cubic Bezier curve with control points p0..p3 (both ends included)."""
    t = np.linspace(0.0, 1.0, n)[:, None]
    u = 1.0 - t
    return u**3 * p0 + 3 * u * u * t * p1 + 3 * u * t * t * p2 + t**3 * p3


def smooth_link(p0: np.ndarray, d0: np.ndarray, p3: np.ndarray, d3: np.ndarray, step: float) -> np.ndarray:
    """A C1 curve from p0 leaving along unit d0 to p3 arriving along unit d3.

    For a real turn the cubic's handles point at the meeting point X of the two tangent lines
    and reach the fraction k = (4/3) tan(theta/4) / tan(theta/2) of the way there (theta =
    heading change): a circular arc when both legs are equally long, and always inside the
    triangle p0-X-p3, so curves of nested lanes stay nested like their curbs. Nearly straight
    moves use handles of (4/3) tan(theta/4) times the radius implied by the chord.
    """
    chord = float(np.hypot(*(p3 - p0)))
    theta = abs(wrap_angle(math.atan2(d3[1], d3[0]) - math.atan2(d0[1], d0[0])))
    n = max(4, math.ceil((chord * (1.0 + theta)) / step) + 1)
    hit = line_intersection(p0, d0, p3, -d3) if theta > math.radians(20.0) else None
    if hit is not None and hit[0] > 0 and hit[1] > 0:
        k = (4.0 / 3.0) * math.tan(theta / 4.0) / math.tan(theta / 2.0)
        return cubic_bezier(p0, p0 + k * hit[0] * d0, p3 - k * hit[1] * d3, p3, n)
    if theta < 1e-3:
        h = chord / 3.0
    else:
        radius = chord / (2.0 * math.sin(theta / 2.0))
        h = min((4.0 / 3.0) * math.tan(theta / 4.0) * radius, 0.9 * chord)
    return cubic_bezier(p0, p0 + h * d0, p3 - h * d3, p3, n)


def line_intersection(
    p: np.ndarray, d: np.ndarray, q: np.ndarray, e: np.ndarray
) -> tuple[float, float] | None:
    """Parameters (a, b) with p + a d = q + b e, or None for (nearly) parallel lines."""
    det = d[0] * (-e[1]) + e[0] * d[1]
    if abs(det) < 1e-9:
        return None
    r = q - p
    a = (r[0] * (-e[1]) + e[0] * r[1]) / det
    b = (d[0] * r[1] - d[1] * r[0]) / det
    return float(a), float(b)


def arc(center: np.ndarray, radius: float, a0: float, a1: float, step: float) -> np.ndarray:
    """Counter-clockwise arc from angle a0 to a1 (a1 > a0) [rad], points every ~`step` [m]."""
    n = max(2, math.ceil(radius * (a1 - a0) / step) + 1)
    a = np.linspace(a0, a1, n)
    return center + radius * np.stack([np.cos(a), np.sin(a)], axis=1)
