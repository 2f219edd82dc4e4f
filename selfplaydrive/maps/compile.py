"""Compile loader output (`MapElements`) into a validated, immutable `RoadMap`.

Validation happens here so every loader gets the same checks and the same `MapError`
messages: finite coordinates, polylines with at least two distinct points, lane-graph indices
in range, a non-empty map.
"""

from __future__ import annotations

from collections.abc import Sequence
from itertools import pairwise

import numpy as np

from selfplaydrive.errors import MapError
from selfplaydrive.maps.elements import LaneElement, MapElements
from selfplaydrive.maps.roadmap import (
    Lanes,
    Polylines,
    RoadMap,
    RoadSegments,
    SegmentGrid,
    SegmentType,
)

DEFAULT_MAX_SEGMENT_LENGTH = 10.0  # [m]
DEFAULT_COLLINEAR_TOL = 0.05  # [m] max deviation when merging nearly collinear points
DEFAULT_CELL_SIZE = 20.0  # [m]


def _check_points(points: np.ndarray, what: str, source: str, element: str, min_len: int = 2) -> np.ndarray:
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise MapError(f"{what} must be an (n, 2) array, got shape {pts.shape}", source, element)
    if not np.all(np.isfinite(pts)):
        raise MapError(f"{what} has non-finite coordinates (NaN or inf)", source, element)
    # drop consecutive duplicates: they carry no direction
    keep = np.ones(len(pts), dtype=bool)
    keep[1:] = np.any(np.abs(np.diff(pts, axis=0)) > 1e-6, axis=1)
    pts = pts[keep]
    if len(pts) < min_len:
        raise MapError(f"{what} needs at least {min_len} distinct points, got {len(pts)}", source, element)
    return pts


def _csr(
    lists: Sequence[Sequence[int]], count: int, what: str, source: str, ids: Sequence[str]
) -> tuple[np.ndarray, np.ndarray]:
    offsets = np.zeros(len(lists) + 1, dtype=np.int32)
    flat: list[int] = []
    for i, items in enumerate(lists):
        for j in items:
            if not 0 <= int(j) < count:
                raise MapError(
                    f"{what} refers to lane index {j}, valid range is [0, {count})", source, ids[i]
                )
            flat.append(int(j))
        offsets[i + 1] = len(flat)
    return offsets, np.asarray(flat, dtype=np.int32)


def _polylines(arrays: Sequence[np.ndarray], shift: np.ndarray) -> Polylines:
    offsets = np.zeros(len(arrays) + 1, dtype=np.int64)
    offsets[1:] = np.cumsum([len(a) for a in arrays]) if arrays else []
    points = np.concatenate(arrays) - shift if arrays else np.zeros((0, 2))
    return Polylines(points=points.astype(np.float32), offsets=offsets)


def simplify_polyline(points: np.ndarray, tol: float) -> np.ndarray:
    """Drop interior points that lie within `tol` [m] of the chord (Douglas-Peucker).

    Args:
        points: (n, 2) float64.
        tol: Max perpendicular deviation [m] of a removed point.

    Returns:
        (m, 2) float64, m <= n, endpoints kept.
    """
    if len(points) <= 2 or tol <= 0:
        return points
    keep = np.zeros(len(points), dtype=bool)
    keep[0] = keep[-1] = True
    stack = [(0, len(points) - 1)]
    while stack:
        i, j = stack.pop()
        if j <= i + 1:
            continue
        a, b = points[i], points[j]
        ab = b - a
        n = np.hypot(ab[0], ab[1])
        rel = points[i + 1 : j] - a
        if n < 1e-9:
            dist = np.hypot(rel[:, 0], rel[:, 1])
        else:
            dist = np.abs(ab[0] * rel[:, 1] - ab[1] * rel[:, 0]) / n
        k = int(np.argmax(dist))
        if dist[k] > tol:
            m = i + 1 + k
            keep[m] = True
            stack.append((i, m))
            stack.append((m, j))
    return points[keep]


def cut_polyline(points: np.ndarray, max_len: float, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Cut a polyline into straight pieces no longer than `max_len` [m].

    Returns:
        (starts, ends): two (k, 2) float64 arrays.
    """
    pts = simplify_polyline(points, tol)
    starts, ends = [], []
    for a, b in pairwise(pts):
        n = max(1, int(np.ceil(np.hypot(*(b - a)) / max_len - 1e-9)))
        t = np.linspace(0.0, 1.0, n + 1)[:, None]
        p = a + t * (b - a)
        starts.append(p[:-1])
        ends.append(p[1:])
    return np.concatenate(starts), np.concatenate(ends)


def _segments(
    groups: Sequence[tuple[SegmentType, Polylines, bool]], max_len: float, tol: float
) -> RoadSegments:
    s_all, e_all, t_all, o_all = [], [], [], []
    for seg_type, lines, closed in groups:
        for i in range(len(lines)):
            pts = lines[i].astype(np.float64)
            if closed:
                pts = np.concatenate([pts, pts[:1]])
            s, e = cut_polyline(pts, max_len, tol)
            s_all.append(s)
            e_all.append(e)
            t_all.append(np.full(len(s), int(seg_type), dtype=np.int8))
            o_all.append(np.full(len(s), i, dtype=np.int32))
    if not s_all:
        z = np.zeros((0, 2), dtype=np.float32)
        return RoadSegments(z, z, z, z, np.zeros(0, np.float32), np.zeros(0, np.int8), np.zeros(0, np.int32))
    start = np.concatenate(s_all)
    end = np.concatenate(e_all)
    d = end - start
    length = np.hypot(d[:, 0], d[:, 1])
    direction = d / np.maximum(length, 1e-9)[:, None]
    return RoadSegments(
        start=start.astype(np.float32),
        end=end.astype(np.float32),
        mid=((start + end) * 0.5).astype(np.float32),
        dir=direction.astype(np.float32),
        length=length.astype(np.float32),
        type=np.concatenate(t_all),
        owner=np.concatenate(o_all),
    )


def build_grid(mid: np.ndarray, bounds: np.ndarray, cell_size: float) -> SegmentGrid:
    """Bucket segment midpoints into a uniform grid (counting sort, CSR layout)."""
    origin = np.asarray(bounds[:2], dtype=np.float32) - cell_size
    nx = int(np.ceil((bounds[2] - bounds[0]) / cell_size)) + 2
    ny = int(np.ceil((bounds[3] - bounds[1]) / cell_size)) + 2
    ix = np.clip(((mid[:, 0] - origin[0]) / cell_size).astype(np.int64), 0, nx - 1)
    iy = np.clip(((mid[:, 1] - origin[1]) / cell_size).astype(np.int64), 0, ny - 1)
    cell = ix * ny + iy
    order = np.argsort(cell, kind="stable").astype(np.int32)
    counts = np.bincount(cell, minlength=nx * ny)
    offsets = np.zeros(nx * ny + 1, dtype=np.int32)
    offsets[1:] = np.cumsum(counts)
    return SegmentGrid(
        origin=origin, cell_size=float(cell_size), shape=(nx, ny), cell_offsets=offsets, cell_items=order
    )


def query_grid_numpy(road_map: RoadMap, x: float, y: float, radius: float) -> np.ndarray:
    """Segment indices with midpoint within `radius` of (x, y); sorted by distance."""
    g = road_map.grid
    nx, ny = g.shape
    lo_x = max(0, int((x - radius - g.origin[0]) // g.cell_size))
    hi_x = min(nx - 1, int((x + radius - g.origin[0]) // g.cell_size))
    lo_y = max(0, int((y - radius - g.origin[1]) // g.cell_size))
    hi_y = min(ny - 1, int((y + radius - g.origin[1]) // g.cell_size))
    found = []
    for ix in range(lo_x, hi_x + 1):
        c0 = ix * ny
        found.append(g.cell_items[g.cell_offsets[c0 + lo_y] : g.cell_offsets[c0 + hi_y + 1]])
    if not found:
        return np.zeros(0, dtype=np.int32)
    cand = np.concatenate(found)
    d2 = np.sum((road_map.segments.mid[cand].astype(np.float64) - (x, y)) ** 2, axis=1)
    inside = d2 <= radius * radius
    cand, d2 = cand[inside], d2[inside]
    return cand[np.argsort(d2, kind="stable")]


def _lanes(elements: MapElements, shift: np.ndarray) -> Lanes:
    src = elements.source
    lanes: list[LaneElement] = elements.lanes
    n = len(lanes)
    ids = [lane.source_id or f"lane[{i}]" for i, lane in enumerate(lanes)]
    lines = [_check_points(lane.centerline, "lane centerline", src, ids[i]) for i, lane in enumerate(lanes)]
    for i, lane in enumerate(lanes):
        for name in ("width", "speed_limit"):
            v = float(getattr(lane, name))
            if not np.isfinite(v) or v <= 0:
                raise MapError(f"lane {name} must be a positive finite number, got {v}", src, ids[i])
    succ_off, succ_idx = _csr([lane.successors for lane in lanes], n, "lane successor", src, ids)
    # predecessors: invert the successor lists
    preds: list[list[int]] = [[] for _ in range(n)]
    for i, lane in enumerate(lanes):
        for j in lane.successors:
            preds[int(j)].append(i)
    pred_off, pred_idx = _csr(preds, n, "lane predecessor", src, ids)
    for i, lane in enumerate(lanes):
        for name in ("left", "right", "twin"):
            j = int(getattr(lane, name))
            if not -1 <= j < n:
                raise MapError(f"lane {name} neighbour index {j} out of range [-1, {n})", src, ids[i])
    return Lanes(
        centerlines=_polylines(lines, shift),
        width=np.array([lane.width for lane in lanes], dtype=np.float32),
        speed_limit=np.array([lane.speed_limit for lane in lanes], dtype=np.float32),
        kind=np.array([int(lane.kind) for lane in lanes], dtype=np.int8),
        in_junction=np.array([lane.in_junction for lane in lanes], dtype=bool),
        twin=np.array([lane.twin for lane in lanes], dtype=np.int32),
        succ_offsets=succ_off,
        succ_index=succ_idx,
        pred_offsets=pred_off,
        pred_index=pred_idx,
        left=np.array([lane.left for lane in lanes], dtype=np.int32),
        left_legal=np.array([lane.left_change_legal for lane in lanes], dtype=bool),
        right=np.array([lane.right for lane in lanes], dtype=np.int32),
        right_legal=np.array([lane.right_change_legal for lane in lanes], dtype=bool),
        source_id=np.array(ids, dtype=str),
    )


def compile_map(
    elements: MapElements,
    max_segment_length: float = DEFAULT_MAX_SEGMENT_LENGTH,
    collinear_tol: float = DEFAULT_COLLINEAR_TOL,
    cell_size: float = DEFAULT_CELL_SIZE,
) -> RoadMap:
    """Validate `elements` and build the `RoadMap`.

    Args:
        elements: Loader output.
        max_segment_length: Longest observed road segment [m].
        collinear_tol: Points within this distance [m] of a straight chord are merged.
        cell_size: Spatial grid cell edge [m].

    Raises:
        MapError: On an empty map, non-finite or degenerate geometry, or dangling indices.
    """
    src = elements.source or elements.name
    if not elements.lanes:
        raise MapError("map has no lanes; a drivable map needs at least one lane", src)
    if not (max_segment_length > 0 and cell_size > 0 and collinear_tol >= 0):
        raise MapError(
            f"compile parameters must be positive: max_segment_length={max_segment_length}, "
            f"cell_size={cell_size}, collinear_tol={collinear_tol}",
            src,
        )
    all_pts = np.concatenate(
        [np.asarray(lane.centerline, dtype=np.float64).reshape(-1, 2) for lane in elements.lanes]
    )
    if not np.all(np.isfinite(all_pts)):
        bad = next(i for i, lane in enumerate(elements.lanes) if not np.all(np.isfinite(lane.centerline)))
        raise MapError(
            "lane centerline has non-finite coordinates (NaN or inf)", src, elements.lanes[bad].source_id
        )
    # recentre on the lane bounding box so float32 keeps ~mm precision anywhere on the map
    shift = np.round((all_pts.min(axis=0) + all_pts.max(axis=0)) / 2.0)
    lanes = _lanes(elements, shift)

    def checked(items: Sequence[object], attr: str, what: str, closed: bool = False) -> list[np.ndarray]:
        min_len = 3 if closed else 2
        return [
            _check_points(getattr(e, attr), what, src, getattr(e, "source_id", "") or f"{what}[{i}]", min_len)
            for i, e in enumerate(items)
        ]

    edges = _polylines(checked(elements.road_edges, "points", "road edge"), shift)
    stops = _polylines(checked(elements.stop_lines, "points", "stop line"), shift)
    lights = _polylines(checked(elements.traffic_lights, "points", "traffic-light stop line"), shift)
    walks = _polylines(checked(elements.crosswalks, "polygon", "crosswalk", closed=True), shift)
    n = len(elements.lanes)
    stop_ids = [e.source_id for e in elements.stop_lines]
    light_ids = [e.source_id for e in elements.traffic_lights]
    stop_off, stop_idx = _csr([e.lanes for e in elements.stop_lines], n, "stop line lane", src, stop_ids)
    light_off, light_idx = _csr(
        [e.lanes for e in elements.traffic_lights], n, "traffic light lane", src, light_ids
    )
    groups = np.array([e.signal_group for e in elements.traffic_lights], dtype=np.int32)
    if len(groups) and groups.min() < 0:
        raise MapError(f"signal groups must be >= 0, got {groups.min()}", src)
    segments = _segments(
        [
            (SegmentType.LANE_CENTER, lanes.centerlines, False),
            (SegmentType.ROAD_EDGE, edges, False),
            (SegmentType.STOP_LINE, stops, False),
            (SegmentType.TRAFFIC_LIGHT, lights, False),
            (SegmentType.CROSSWALK, walks, True),
        ],
        max_segment_length,
        collinear_tol,
    )
    geo = np.concatenate([segments.start, segments.end])
    bounds = np.concatenate([geo.min(axis=0), geo.max(axis=0)]).astype(np.float32)
    return RoadMap(
        name=elements.name,
        source=elements.source,
        origin=np.asarray(elements.frame_origin, dtype=np.float64) + shift,
        crs=elements.crs,
        lanes=lanes,
        road_edges=edges,
        edge_kind=np.array([int(e.kind) for e in elements.road_edges], dtype=np.int8),
        stop_lines=stops,
        stop_kind=np.array([int(e.kind) for e in elements.stop_lines], dtype=np.int8),
        stop_lane_offsets=stop_off,
        stop_lane_index=stop_idx,
        light_lines=lights,
        light_group=groups,
        light_lane_offsets=light_off,
        light_lane_index=light_idx,
        crosswalks=walks,
        segments=segments,
        grid=build_grid(segments.mid, bounds, cell_size),
        bounds=bounds,
        max_segment_length=float(max_segment_length),
    )
