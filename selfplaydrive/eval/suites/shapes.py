"""Polygon helpers of the failure-mode suites: vehicle boxes, lane areas and lateral offsets.

Everything is float64 in the map's local frame [m] and built with shapely's vectorised
constructors, so a whole trajectory's boxes cost one call.
"""

from __future__ import annotations

import numpy as np
import shapely

from selfplaydrive.maps.lane_paths import LaneGeometry, cumlen, point_at


def box_corners(xy: np.ndarray, heading: np.ndarray, length: np.ndarray, width: np.ndarray) -> np.ndarray:
    """(n, 4, 2) corners of oriented boxes, counter-clockwise.

    Args:
        xy: (n, 2) centres [m]; heading (n,) [rad]; length, width (n,) or scalars [m].
    """
    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    h = np.asarray(heading, np.float64).reshape(-1)
    u = np.stack([np.cos(h), np.sin(h)], axis=1)
    v = np.stack([-u[:, 1], u[:, 0]], axis=1)
    hl = np.broadcast_to(np.asarray(length, np.float64) / 2, h.shape)[:, None]
    hw = np.broadcast_to(np.asarray(width, np.float64) / 2, h.shape)[:, None]
    signs = ((1, 1), (-1, 1), (-1, -1), (1, -1))  # front-left, rear-left, rear-right, front-right
    return np.stack([xy + a * hl * u + b * hw * v for a, b in signs], axis=1)


def box_polygons(xy: np.ndarray, heading: np.ndarray, length, width) -> np.ndarray:
    """(n,) shapely Polygons of oriented boxes (see `box_corners`)."""
    return shapely.polygons(box_corners(xy, heading, length, width))


def swept_boxes(xy: np.ndarray, heading: np.ndarray, length, width, reach: np.ndarray) -> np.ndarray:
    """(n,) Polygons covered by boxes moving `reach` [m] straight ahead: the box stretched
    forward (the convex hull of the start and end boxes of a straight motion)."""
    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    h = np.asarray(heading, np.float64).reshape(-1)
    reach = np.broadcast_to(np.asarray(reach, np.float64), h.shape)
    u = np.stack([np.cos(h), np.sin(h)], axis=1)
    ln = np.broadcast_to(np.asarray(length, np.float64), h.shape)
    return box_polygons(xy + u * (reach / 2)[:, None], h, ln + reach, width)


def lane_polygons(geo: LaneGeometry, lanes: np.ndarray) -> np.ndarray:
    """(len(lanes),) Polygons of lanes: centerline buffered by half the lane width, flat ends
    (a round end would reach half a width past the stop line into the junction)."""
    lines = [shapely.LineString(geo.line(i)) for i in lanes]
    widths = np.asarray(geo.lanes.width, np.float64)[np.asarray(lanes, np.int64)]
    return shapely.buffer(np.array(lines, dtype=object), widths / 2, cap_style="flat")


def offset_path(
    path: np.ndarray,
    offset: float,
    ramp: tuple[float, float],
    step: float = 0.5,
    back: tuple[float, float] | None = None,
) -> np.ndarray:
    """`path` shifted `offset` [m] to the left, the shift growing smoothly (cosine) from 0 at
    arc `ramp[0]` to the full offset at `ramp[1]` and kept to the end, or, with `back`, falling
    back to 0 between arcs `back[0]` and `back[1]` (a swerve out and back in).

    Returns:
        (n, 2) float64 polyline resampled every `step` m.
    """
    s = np.arange(0.0, cumlen(path)[-1] + 1e-9, step)
    xy, hd = point_at(path, s)
    f = np.clip((s - ramp[0]) / max(ramp[1] - ramp[0], 1e-6), 0.0, 1.0)
    shift = offset * (1 - np.cos(np.pi * f)) / 2
    if back is not None:
        g = np.clip((s - back[0]) / max(back[1] - back[0], 1e-6), 0.0, 1.0)
        shift = shift * (1 + np.cos(np.pi * g)) / 2
    left = np.stack([-np.sin(hd), np.cos(hd)], axis=1)
    return xy + shift[:, None] * left
