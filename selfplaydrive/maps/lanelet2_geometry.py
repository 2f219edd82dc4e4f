"""Planar geometry of Lanelet2 lanelets: bound orientation, centerlines, widths (numpy only)."""

from __future__ import annotations

import numpy as np


def polyline_length(points: np.ndarray) -> float:
    """Length of an (n, 2) polyline [m]."""
    return float(np.hypot(*np.diff(points, axis=0).T).sum()) if len(points) > 1 else 0.0


def signed_distance(line: np.ndarray, point: np.ndarray) -> float:
    """Signed distance [m] of `point` (2,) to the (n >= 2, 2) polyline `line`.

    Positive when the point lies left of the line (seen along its direction), negative when
    right, measured at the closest segment.
    """
    a, b = line[:-1], line[1:]
    ab = b - a
    ab2 = np.einsum("ij,ij->i", ab, ab)
    t = np.clip(np.einsum("ij,ij->i", point - a, ab) / np.maximum(ab2, 1e-18), 0.0, 1.0)
    closest = a + t[:, None] * ab
    d = np.hypot(*(point - closest).T)
    k = int(np.argmin(d))
    rel = point - a[k]
    cross = ab[k, 0] * rel[1] - ab[k, 1] * rel[0]
    return float(d[k] if cross >= 0 else -d[k])


def _middle(points: np.ndarray) -> np.ndarray:
    # Lanelet2's choice of probe point: the middle vertex, or the chord midpoint of a 2-point line
    return points[len(points) // 2] if len(points) > 2 else (points[0] + points[-1]) * 0.5


def align_bounds(left: np.ndarray, right: np.ndarray) -> tuple[bool, bool]:
    """Decide which bounds to reverse so both run in the lanelet's direction of travel.

    The roles are trusted and the stored point order is not: the left bound must have the right
    bound on its right side and vice versa. This is the rule the official Lanelet2 loader
    applies (`lanelet::geometry::align`); about half of Tartu's bounds are stored reversed.

    Args:
        left: (n, 2) points of the way with role "left", as stored [m].
        right: (m, 2) points of the way with role "right", as stored [m].

    Returns:
        (reverse_left, reverse_right).
    """
    rev_left = signed_distance(left, _middle(right)) >= 0.0
    if rev_left:
        left = left[::-1]
    rev_right = signed_distance(right, _middle(left)) <= 0.0
    return bool(rev_left), bool(rev_right)


def _arc_ratios(points: np.ndarray) -> np.ndarray:
    seg = np.hypot(*np.diff(points, axis=0).T)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    return cum / cum[-1] if cum[-1] > 0 else np.linspace(0.0, 1.0, len(points))


def _at_ratios(points: np.ndarray, ratios: np.ndarray, at: np.ndarray) -> np.ndarray:
    return np.stack([np.interp(at, ratios, points[:, 0]), np.interp(at, ratios, points[:, 1])], axis=-1)


def centerline_and_width(left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, float]:
    """Centerline and mean width of a lanelet from its oriented bounds.

    Both bounds are parametrised by normalised arc length; the centerline is the average of the
    two at every vertex position of either bound (so no bound corner is cut off).

    Args:
        left: (n, 2) oriented left bound [m].
        right: (m, 2) oriented right bound [m].

    Returns:
        (centerline (k, 2) [m], width [m]): width is the length-weighted mean distance between
        the corresponding bound points.
    """
    rl, rr = _arc_ratios(left), _arc_ratios(right)
    at = np.unique(np.concatenate([rl, rr]))
    pl, pr = _at_ratios(left, rl, at), _at_ratios(right, rr, at)
    center = (pl + pr) * 0.5
    gap = np.hypot(*(pl - pr).T)
    seg = np.hypot(*np.diff(center, axis=0).T)
    total = seg.sum()
    width = float(((gap[:-1] + gap[1:]) * 0.5 * seg).sum() / total) if total > 1e-9 else float(gap.mean())
    return center, width


def orient_like(line: np.ndarray, start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """Return `line` or its reverse, whichever starts nearer `start` and ends nearer `end`."""
    fwd = np.hypot(*(line[0] - start)) + np.hypot(*(line[-1] - end))
    bwd = np.hypot(*(line[-1] - start)) + np.hypot(*(line[0] - end))
    return line if fwd <= bwd else line[::-1]


def dedupe(points: np.ndarray, tol: float = 1e-6) -> np.ndarray:
    """Drop consecutive points closer than `tol` [m]."""
    if len(points) < 2:
        return points
    keep = np.ones(len(points), dtype=bool)
    keep[1:] = np.hypot(*np.diff(points, axis=0).T) > tol
    return points[keep]
