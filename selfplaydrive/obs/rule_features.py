"""Traffic-rule features of the road: STOP/YIELD line kinds and crosswalk occupancy (issue #15
item 1; docs/observation.md "Traffic-rule features").

The one place for the rule's constants and its geometry, shared by the `obs=rules` encoder
(obs/rules.py, _sim/obs_rules.pyx) and the reward terms that depend on the same state (`stop_sign`,
`crosswalk_yield`): a crosswalk is *occupied* when a present pedestrian's centre, or its centre
`CROSSWALK_HORIZON` seconds ahead at its current velocity, lies inside the crosswalk polygon
grown by `CROSSWALK_MARGIN` metres (inside the polygon, or within the margin of its outline).
The functions here are the plain NumPy form (float64, written for clarity); the kernel does the
same arithmetic in C doubles.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from selfplaydrive.maps.roadmap import RoadMap, SegmentType, StopKind

CROSSWALK_MARGIN = 0.5  # [m] the crosswalk polygon is grown by this much
CROSSWALK_HORIZON = 1.5  # [s] a pedestrian "about to enter": centre + velocity * horizon inside

# Road-row values of the `obs=rules` encoder (columns of obs/layout.py ROAD_FEATURES). The paper
# writes SegmentType / 4 in "type": every stop line is 0.5 (section 2.1 treats them all as yield
# lines), so YIELD lines keep 0.5 and STOP lines get a value no other type has.
YIELD_LINE_TYPE = int(SegmentType.STOP_LINE) / 4.0  # 0.5, the paper's value
STOP_LINE_TYPE = (int(SegmentType.STOP_LINE) + 0.5) / 4.0  # 0.625, between stop 0.5 and light 0.75
# The "light_state" column is 0 on every segment but a traffic-light line; on a crosswalk
# segment whose crosswalk is occupied the encoder writes this instead.
CROSSWALK_OCCUPIED = 1.0

# per atlas position (RuleMapData.seg_code): nothing to mark, a STOP-kind line, else the
# crosswalk's global index (>= 0)
CODE_NONE = -1
CODE_STOP = -2


def inside_grown_polygon(x: np.ndarray, y: np.ndarray, polygon: np.ndarray, margin: float) -> np.ndarray:
    """Whether each point lies inside `polygon` or within `margin` of its outline.

    Args:
        x, y: (n,) point coordinates [m].
        polygon: (k, 2) outline [m], open (the last point joins the first), k >= 1.
        margin: [m] growth of the polygon (>= 0).

    Returns:
        (n,) bool.
    """
    px = np.asarray(x, dtype=np.float64)
    py = np.asarray(y, dtype=np.float64)
    poly = np.asarray(polygon, dtype=np.float32).astype(np.float64)
    inside = np.zeros(px.shape, dtype=bool)
    near = np.zeros(px.shape, dtype=bool)
    m2 = float(margin) * float(margin)
    k = len(poly)
    for e in range(k):
        ax, ay = poly[e]
        bx, by = poly[(e + 1) % k]
        # crossing number: the edge straddles the point's horizontal line right of the point
        straddles = (ay > py) != (by > py)
        with np.errstate(divide="ignore", invalid="ignore"):
            cross_x = (bx - ax) * (py - ay) / (by - ay) + ax
        inside ^= straddles & (px < cross_x)
        # distance to the edge
        ex, ey = bx - ax, by - ay
        ll = ex * ex + ey * ey
        t = np.zeros(px.shape) if ll <= 0.0 else ((px - ax) * ex + (py - ay) * ey) / ll
        t = np.clip(t, 0.0, 1.0)
        dx = px - (ax + t * ex)
        dy = py - (ay + t * ey)
        near |= dx * dx + dy * dy <= m2
    return inside | near


def pedestrians_on_crosswalk(
    polygon: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    vx: np.ndarray,
    vy: np.ndarray,
    margin: float = CROSSWALK_MARGIN,
    horizon: float = CROSSWALK_HORIZON,
) -> np.ndarray:
    """(n,) bool: pedestrian on the crosswalk or about to enter it (the module's rule).

    Args:
        polygon: (k, 2) crosswalk outline [m] (`RoadMap.crosswalks[c]`).
        x, y: (n,) pedestrian centres [m] (present pedestrians only).
        vx, vy: (n,) velocities [m/s].
        margin: [m] growth of the polygon.
        horizon: [s] look-ahead of "about to enter".
    """
    x64, y64 = np.asarray(x, np.float32).astype(np.float64), np.asarray(y, np.float32).astype(np.float64)
    vx64, vy64 = np.asarray(vx, np.float32).astype(np.float64), np.asarray(vy, np.float32).astype(np.float64)
    now = inside_grown_polygon(x64, y64, polygon, margin)
    ahead = inside_grown_polygon(x64 + vx64 * horizon, y64 + vy64 * horizon, polygon, margin)
    return now | ahead


def crosswalk_polygons(road_map: RoadMap) -> list[np.ndarray]:
    """The crosswalk outlines of a map, (k, 2) float32 each [m]."""
    return [np.asarray(road_map.crosswalks[c]) for c in range(len(road_map.crosswalks))]


@dataclass(frozen=True)
class RuleMapData:
    """The rule features' view of an env's maps, indexed like its atlas (sim/atlas.py).

    Attributes:
        seg_code: (Ns,) int32 per atlas position: `CODE_STOP` (a STOP-kind stop line),
            the segment's global crosswalk index (a crosswalk outline), or `CODE_NONE`.
        map_cw: (M + 1,) int32: crosswalks of map m are global indices [map_cw[m], map_cw[m + 1]).
        map_stop: (M,) int32 STOP-kind line segments of each map.
        cw_pts: (C + 1,) int32: outline of crosswalk c is pts[cw_pts[c]:cw_pts[c + 1]].
        pts: (P, 2) float32 [m] outline points of every crosswalk.
        cw_box: (C, 4) float32 [m] xmin, ymin, xmax, ymax of each outline, grown by more than
            the margin (a test that rejects only points certainly outside).
        grid_origin: (M, 3) float32 [m] lower-left corner and cell edge of each map's
            crosswalk grid.
        grid_dims: (M, 3) int32 cells along x and y, and the map's first entry in cell_start.
        cell_start: CSR over the cells of every map: cell (ix, iy) of map m lists
            cell_items[cell_start[b + ix * ny + iy] : cell_start[b + ix * ny + iy + 1]], with b
            = grid_dims[m, 2] (each map's part has nx * ny + 1 entries).
        cell_items: int32 global crosswalk indices whose grown box meets the cell.
        stop_grid: (M, 3) float32 [m] lower-left corner and cell edge of each map's grid of
            STOP-line segment midpoints.
        stop_dims: (M, 3) int32 cells along x and y, and the map's first entry in stop_sat.
        stop_sat: int32 summed-area tables of STOP-line midpoints per cell, (nx + 1) * (ny + 1)
            entries per map: entry (i, j) counts the midpoints in cells [0, i) x [0, j) (a
            rectangle of cells is counted with four reads).
    """

    seg_code: np.ndarray
    map_cw: np.ndarray
    map_stop: np.ndarray
    cw_pts: np.ndarray
    pts: np.ndarray
    cw_box: np.ndarray
    grid_origin: np.ndarray
    grid_dims: np.ndarray
    cell_start: np.ndarray
    cell_items: np.ndarray
    stop_grid: np.ndarray
    stop_dims: np.ndarray
    stop_sat: np.ndarray


def rule_map_data(
    maps: Sequence[RoadMap], atlas: Mapping[str, np.ndarray], margin: float = CROSSWALK_MARGIN
) -> RuleMapData:
    """Build `RuleMapData` from an env's maps and its atlas (`build_atlas(maps)`).

    Raises:
        ValueError: The atlas was not built from these maps (segment counts differ).
    """
    sizes = [len(m.segments) for m in maps]
    ns = int(np.asarray(atlas["seg_rec"]).shape[0])
    if ns != sum(sizes):
        raise ValueError(f"atlas: {ns} segments, the maps have {sum(sizes)}: build it from the same maps")
    seg_base = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    cw_count = [len(m.crosswalks) for m in maps]
    map_cw = np.concatenate([[0], np.cumsum(cw_count)]).astype(np.int32)
    code_global = np.full(ns, CODE_NONE, dtype=np.int32)
    map_stop = np.zeros(len(maps), dtype=np.int32)
    polys: list[np.ndarray] = []
    for m, road_map in enumerate(maps):
        seg = road_map.segments
        code = np.full(len(seg), CODE_NONE, dtype=np.int32)
        stop = seg.type == int(SegmentType.STOP_LINE)
        stop[stop] = road_map.stop_kind[seg.owner[stop]] == int(StopKind.STOP)
        code[stop] = CODE_STOP
        walk = seg.type == int(SegmentType.CROSSWALK)
        code[walk] = seg.owner[walk] + map_cw[m]
        code_global[seg_base[m] : seg_base[m + 1]] = code
        map_stop[m] = int(stop.sum())
        polys += crosswalk_polygons(road_map)
    seg_id = np.asarray(atlas["seg_id"])[:ns]
    cw_pts = np.concatenate([[0], np.cumsum([len(p) for p in polys])]).astype(np.int32)
    pts = np.concatenate(polys).astype(np.float32) if polys else np.zeros((0, 2), np.float32)
    grow = float(margin) + 0.01  # a little more than the margin: float32 rounding stays inside
    box = np.zeros((len(polys), 4), dtype=np.float32)
    box[:, :2], box[:, 2:] = np.inf, -np.inf  # an outline without points holds nothing
    for c, p in enumerate(polys):
        if len(p):
            box[c] = (*(p.min(axis=0) - grow), *(p.max(axis=0) + grow))
    return RuleMapData(
        np.ascontiguousarray(code_global[seg_id]),
        map_cw,
        map_stop,
        cw_pts,
        np.ascontiguousarray(pts),
        box,
        *crosswalk_grids(box, map_cw, GRID_CELL),
        *stop_tables(code_global, seg_base, np.asarray(atlas["seg_rec"])[:, :2], seg_id, STOP_CELL),
    )


GRID_CELL = 10.0  # [m] cell edge of the crosswalk grids (a crosswalk meets a few cells)
MAX_GRID_CELLS = 1 << 20  # per map; larger maps get larger cells (x2 until they fit)


def crosswalk_grids(
    box: np.ndarray, map_cw: np.ndarray, cell: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per map, a uniform grid listing in each cell the crosswalks whose box meets it (the
    kernel tests a pedestrian's point against the crosswalks of its cell only). Returns
    (grid_origin, grid_dims, cell_start, cell_items) as `RuleMapData` describes them; a cell
    index is floor((x - origin) / cell) in float64, as in the kernel."""
    M = len(map_cw) - 1
    origin = np.zeros((M, 3), np.float32)
    dims = np.zeros((M, 3), np.int32)
    starts: list[np.ndarray] = []
    items: list[np.ndarray] = []
    base = n_items = 0
    for m in range(M):
        b = box[map_cw[m] : map_cw[m + 1]].astype(np.float64)
        b = b[np.isfinite(b).all(axis=1)]
        lo = b[:, :2].min(axis=0) if len(b) else np.zeros(2)
        hi = b[:, 2:].max(axis=0) if len(b) else np.zeros(2)
        size = float(cell)
        while (int((hi[0] - lo[0]) // size) + 1) * (int((hi[1] - lo[1]) // size) + 1) > MAX_GRID_CELLS:
            size *= 2.0
        origin[m] = (lo[0] - 1.0, lo[1] - 1.0, size)  # 1 m below: float32 rounding stays inside
        o = origin[m].astype(np.float64)
        nx = int(np.floor((hi[0] - o[0]) / size)) + 1
        ny = int(np.floor((hi[1] - o[1]) / size)) + 1
        lists: list[list[int]] = [[] for _ in range(nx * ny)]
        for c in range(map_cw[m], map_cw[m + 1]):
            x0, y0, x1, y1 = box[c].astype(np.float64)
            if not np.isfinite(x0):
                continue
            ix0, iy0 = max(int(np.floor((x0 - o[0]) / size)), 0), max(int(np.floor((y0 - o[1]) / size)), 0)
            ix1 = min(int(np.floor((x1 - o[0]) / size)), nx - 1)
            iy1 = min(int(np.floor((y1 - o[1]) / size)), ny - 1)
            for ix in range(ix0, ix1 + 1):
                for iy in range(iy0, iy1 + 1):
                    lists[ix * ny + iy].append(c)
        counts = np.array([len(v) for v in lists], np.int64)
        starts.append((np.concatenate([[0], np.cumsum(counts)]) + n_items).astype(np.int32))
        items += [np.asarray(v, np.int32) for v in lists if v]
        dims[m] = (nx, ny, base)
        base += nx * ny + 1
        n_items += int(counts.sum())
    cell_items = np.concatenate(items).astype(np.int32) if items else np.zeros(0, np.int32)
    return origin, dims, np.concatenate(starts), cell_items


STOP_CELL = 20.0  # [m] cell edge of the STOP-line count grids


def stop_tables(
    code: np.ndarray, seg_base: np.ndarray, mid: np.ndarray, seg_id: np.ndarray, cell: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per map, a grid of cells counting STOP-line segment midpoints, as a summed-area table:
    the kernel asks "any STOP line in this square?" with four reads, to pass over the rows of
    agents that see none. `code`: per global segment (CODE_STOP or not); `mid`: the atlas's
    midpoints (atlas order, `seg_id` their global indices). Returns (stop_grid, stop_dims,
    stop_sat) as `RuleMapData` describes them."""
    M = len(seg_base) - 1
    grid = np.zeros((M, 3), np.float32)
    dims = np.zeros((M, 3), np.int32)
    sats: list[np.ndarray] = []
    base = 0
    for m in range(M):
        pos = np.flatnonzero((seg_id >= seg_base[m]) & (seg_id < seg_base[m + 1]))
        pos = pos[code[seg_id[pos]] == CODE_STOP]
        p = mid[pos].astype(np.float64)
        lo = p.min(axis=0) if len(p) else np.zeros(2)
        hi = p.max(axis=0) if len(p) else np.zeros(2)
        size = float(cell)
        while (int((hi[0] - lo[0]) // size) + 2) * (int((hi[1] - lo[1]) // size) + 2) > MAX_GRID_CELLS:
            size *= 2.0
        grid[m] = (lo[0] - 1.0, lo[1] - 1.0, size)  # 1 m below: float32 rounding stays inside
        o = grid[m].astype(np.float64)
        nx = int(np.floor((hi[0] - o[0]) / size)) + 1
        ny = int(np.floor((hi[1] - o[1]) / size)) + 1
        counts = np.zeros((nx, ny), np.int64)
        if len(p):
            ix = np.floor((p[:, 0] - o[0]) / size).astype(np.int64)
            iy = np.floor((p[:, 1] - o[1]) / size).astype(np.int64)
            np.add.at(counts, (ix, iy), 1)
        sat = np.zeros((nx + 1, ny + 1), np.int64)
        sat[1:, 1:] = counts.cumsum(axis=0).cumsum(axis=1)
        sats.append(sat.astype(np.int32).ravel())
        dims[m] = (nx, ny, base)
        base += (nx + 1) * (ny + 1)
    return grid, dims, np.concatenate(sats)
