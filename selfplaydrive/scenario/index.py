"""Per-map tables the spawner precomputes once, so one world reset stays around a millisecond.

`MapIndex.build(road_map)` computes:
- route tables (lane arc lengths, successor CSR without bicycle lanes; `maps.routing`);
- spawn chunks: the spawnable lanes (vehicle or bus lanes outside junctions) cut into pieces of
  at most `chunk_length` m, bucketed by grid cell of their midpoint;
- roadside chunks: pieces of rightmost lanes (no right neighbour) whose right side is a road
  edge within `edge_search` m of the lane border, with no other lane in between (probed at
  both ends and the middle of each chunk), at least `parking_clearance` m from crosswalks and
  from junctions at the lane's ends, and the distance from the centreline to that edge;
- pedestrian crossings: edge-to-edge paths across the road perpendicular to a lane, and the
  long axis of every crosswalk polygon;
- region centres: a lattice of candidate 200 x 200 m region centres with enough spawnable lane.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import shapely

from selfplaydrive.maps.elements import LaneKind
from selfplaydrive.maps.roadmap import RoadMap, SegmentType
from selfplaydrive.maps.routing import RouteTables, route_tables


@dataclass(frozen=True)
class CellIndex:
    """Points bucketed into square cells, each x column stored contiguously (cell = ix * ny + iy).

    Attributes:
        origin: (2,) float64 [m] lower-left corner of cell (0, 0).
        cell: Cell edge [m].
        shape: (nx, ny).
        offsets: (nx * ny + 1,) int64 CSR offsets into `items`.
        items: (N,) int64 point indices sorted by cell.
        xy: (N, 2) float64 the bucketed points [m] (original order).
    """

    origin: np.ndarray
    cell: float
    shape: tuple[int, int]
    offsets: np.ndarray
    items: np.ndarray
    xy: np.ndarray

    @classmethod
    def build(cls, xy: np.ndarray, cell: float) -> CellIndex:
        """Bucket (N, 2) points into cells of `cell` m."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        lo = xy.min(axis=0) if len(xy) else np.zeros(2)
        hi = xy.max(axis=0) if len(xy) else np.zeros(2)
        nx, ny = (int(v) + 1 for v in np.floor((hi - lo) / cell))
        ix = ((xy[:, 0] - lo[0]) // cell).astype(np.int64)
        iy = ((xy[:, 1] - lo[1]) // cell).astype(np.int64)
        c = ix * ny + iy
        order = np.argsort(c, kind="stable").astype(np.int64)
        offsets = np.concatenate([[0], np.cumsum(np.bincount(c, minlength=nx * ny))]).astype(np.int64)
        return cls(lo, float(cell), (nx, ny), offsets, order, xy)

    def query_box(self, box: np.ndarray) -> np.ndarray:
        """Indices of the points inside box = (xmin, ymin, xmax, ymax) [m], in cell order."""
        nx, ny = self.shape
        ix0, iy0 = (max(0, int((box[k] - self.origin[k]) // self.cell)) for k in (0, 1))
        ix1 = min(nx - 1, int((box[2] - self.origin[0]) // self.cell))
        iy1 = min(ny - 1, int((box[3] - self.origin[1]) // self.cell))
        if ix1 < ix0 or iy1 < iy0:
            return np.zeros(0, dtype=np.int64)
        parts = [
            self.items[self.offsets[i * ny + iy0] : self.offsets[i * ny + iy1 + 1]]
            for i in range(ix0, ix1 + 1)
        ]
        cand = np.concatenate(parts)
        p = self.xy[cand]
        inside = (p[:, 0] >= box[0]) & (p[:, 0] <= box[2]) & (p[:, 1] >= box[1]) & (p[:, 1] <= box[3])
        return cand[inside]


@dataclass(frozen=True)
class Chunks:
    """Lane pieces: chunk i covers lane `lane[i]` from `s0[i]` to `s1[i]` [m].

    Attributes:
        lane: (N,) int64.
        s0, s1: (N,) float64 [m].
        edge: (N,) float64 distance [m] from the centreline to the road edge on the right
            (inf for spawn chunks, which do not look for it).
        cells: `CellIndex` over the chunk midpoints.
    """

    lane: np.ndarray
    s0: np.ndarray
    s1: np.ndarray
    edge: np.ndarray
    cells: CellIndex


@dataclass(frozen=True)
class Crossings:
    """Straight pedestrian crossings. start/end: (N, 2) float64 [m]; half_width: (N,) [m] of
    sideways jitter allowed (crosswalk half width, 0 elsewhere); cells index the midpoints."""

    start: np.ndarray
    end: np.ndarray
    half_width: np.ndarray
    cells: CellIndex

    @cached_property
    def kernel(self) -> object:
        """The arrays bound once to the pedestrian kernels (`_sim.pedestrians.CrossingKernel`)."""
        from selfplaydrive._sim.pedestrians import CrossingKernel

        return CrossingKernel(self)


def _cut_lanes(t: RouteTables, lanes: np.ndarray, chunk: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cut lanes into pieces of at most `chunk` m: (lane, s0, s1)."""
    n = np.maximum(np.ceil(t.length[lanes] / chunk), 1).astype(np.int64)
    lane = np.repeat(lanes, n)
    k = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
    step = t.length[lane] / np.repeat(n, n)
    return lane, k * step, (k + 1) * step


def ray_hits(
    origin: np.ndarray, direction: np.ndarray, max_len: float, a: np.ndarray, b: np.ndarray
) -> tuple:
    """All hits of rays with segments (precompute only; uses shapely's STRtree).

    Args:
        origin, direction: (N, 2) ray starts [m] and unit directions.
        max_len: Ray length [m].
        a, b: (M, 2) segment endpoints [m].

    Returns:
        (ray index (H,), segment index (H,), distance along the ray (H,) [m]).
    """
    if len(a) == 0 or len(origin) == 0:
        z = np.zeros(0, dtype=np.int64)
        return z, z, np.zeros(0)
    tree = shapely.STRtree(shapely.linestrings(np.stack([a, b], axis=1)))
    rays = shapely.linestrings(np.stack([origin, origin + direction * max_len], axis=1))
    ri, si = tree.query(rays, predicate="intersects")
    d, e = direction[ri], b[si] - a[si]
    w = a[si] - origin[ri]
    den = d[:, 0] * e[:, 1] - d[:, 1] * e[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(np.abs(den) > 1e-12, (w[:, 0] * e[:, 1] - w[:, 1] * e[:, 0]) / den, 0.0)
    return ri, si, np.clip(t, 0.0, max_len)


def _min_hit(n: int, ri: np.ndarray, dist: np.ndarray) -> np.ndarray:
    out = np.full(n, np.inf)
    np.minimum.at(out, ri, dist)
    return out


def _side_distance(road_map: RoadMap, xy: np.ndarray, direction: np.ndarray, max_len: float) -> np.ndarray:
    """Distance [m] along each ray to the nearest road edge (inf if none within max_len)."""
    seg = road_map.segments
    edge = seg.type == SegmentType.ROAD_EDGE
    ri, _, dist = ray_hits(
        xy, direction, max_len, seg.start[edge].astype(np.float64), seg.end[edge].astype(np.float64)
    )
    return _min_hit(len(xy), ri, dist)


def _lane_between(road_map: RoadMap, xy: np.ndarray, direction: np.ndarray, max_len: float) -> np.ndarray:
    """Distance [m] to the nearest other lane centreline along each ray (hits under 0.5 m are the
    lane itself or its twin)."""
    seg = road_map.segments
    m = seg.type == SegmentType.LANE_CENTER
    ri, _, dist = ray_hits(
        xy, direction, max_len, seg.start[m].astype(np.float64), seg.end[m].astype(np.float64)
    )
    far = dist > 0.5
    return _min_hit(len(xy), ri[far], dist[far])


def _right_normal(heading: np.ndarray) -> np.ndarray:
    return np.stack([np.sin(heading), -np.cos(heading)], axis=1)


@dataclass(frozen=True)
class MapIndex:
    """Everything the spawner precomputes for one map (see the module docstring).

    Attributes:
        road_map: The map.
        routes: `RouteTables` of the map.
        spawn: Spawn chunks on vehicle lanes outside junctions.
        roadside: Chunks of rightmost lanes with a roadside (`edge` = right edge distance).
        crossings: Pedestrian crossings away from crosswalks.
        crosswalks: Pedestrian crossings along crosswalks.
        centres: (C, 2) float64 candidate region centres [m].
        centre_lane_length: (C,) float64 spawnable lane length [m] inside each candidate region.
        region_size: Region edge [m].
        region_stride: Lattice spacing of the centres [m]; a sampled centre is jittered by
            U(-stride/2, stride/2) on each axis.
    """

    road_map: RoadMap
    routes: RouteTables
    spawn: Chunks
    roadside: Chunks
    crossings: Crossings
    crosswalks: Crossings
    centres: np.ndarray
    centre_lane_length: np.ndarray
    region_size: float
    region_stride: float

    @classmethod
    def build(
        cls,
        road_map: RoadMap,
        region_size: float = 200.0,
        region_stride: float = 20.0,
        min_region_lane_length: float = 1500.0,
        chunk_length: float = 5.0,
        cell_size: float = 25.0,
        edge_search: float = 6.0,
        max_crossing_length: float = 30.0,
        parking_clearance: float = 5.0,
    ) -> MapIndex:
        """Build the index (vectorised; seconds even for large maps).

        Args:
            road_map: The map.
            region_size: Edge of the square spawn region [m] (200 in section 2.2).
            region_stride: Spacing of candidate region centres [m].
            min_region_lane_length: A region centre qualifies when its region holds at least this
                much spawnable lane [m]; when none does, the centres with at least half of the
                best region's length are used instead (small maps).
            chunk_length: Longest spawn / roadside chunk [m].
            cell_size: Cell of the chunk buckets [m].
            edge_search: How far beyond the lane edge to look for the road edge [m].
            max_crossing_length: Longest edge-to-edge pedestrian crossing [m].
            parking_clearance: No roadside spot within this distance [m] of a crosswalk or of a
                junction at the end of its lane.
        """
        t = route_tables(road_map)
        lanes = road_map.lanes
        ok = (lanes.kind != LaneKind.BICYCLE) & ~lanes.in_junction
        spawn = _chunks(t, np.flatnonzero(ok), chunk_length, cell_size)
        rightmost = np.flatnonzero(ok & (lanes.right < 0))
        roadside = _roadside(road_map, t, rightmost, chunk_length, cell_size, edge_search, parking_clearance)
        crossings = _crossings(road_map, t, spawn, max_crossing_length, cell_size)
        crosswalks = _crosswalks(road_map, cell_size)
        centres, length = _centres(
            t, spawn, road_map.bounds, region_size, region_stride, min_region_lane_length
        )
        return cls(
            road_map, t, spawn, roadside, crossings, crosswalks, centres, length, region_size, region_stride
        )

    @cached_property
    def num_signal_groups(self) -> int:
        """`RoadMap.num_signal_groups` of the map (computed once; a reset needs it twice)."""
        return self.road_map.num_signal_groups

    @cached_property
    def kernels(self) -> SpawnKernels:
        """The index's arrays bound once to the Cython kernels of a world reset."""
        from selfplaydrive._sim.chunks import ChunkKernel
        from selfplaydrive._sim.waypoints import RouteKernel

        lanes = self.road_map.lanes
        routes = RouteKernel(self.routes, lanes.width, lanes.speed_limit)
        return SpawnKernels(routes, ChunkKernel(self.spawn, routes), ChunkKernel(self.roadside, routes))


@dataclass(frozen=True)
class SpawnKernels:
    """`MapIndex.kernels`: route walks and waypoints (`routes`), pose draws on the spawn and
    roadside chunks (`_sim/waypoints.pyx` `RouteKernel`, `_sim/chunks.pyx` `ChunkKernel`)."""

    routes: object
    spawn: object
    roadside: object

    def chunks(self, index: MapIndex, chunks: Chunks) -> object:
        """The kernel of `chunks` (index.spawn or index.roadside)."""
        if chunks is index.spawn:
            return self.spawn
        if chunks is index.roadside:
            return self.roadside
        from selfplaydrive._sim.chunks import ChunkKernel

        return ChunkKernel(chunks, self.routes)


def _chunks(
    t: RouteTables, lanes: np.ndarray, chunk: float, cell: float, edge: np.ndarray | None = None
) -> Chunks:
    lane, s0, s1 = _cut_lanes(t, lanes.astype(np.int64), chunk)
    mid, _ = t.points(lane, (s0 + s1) / 2)
    edge = np.full(len(lane), np.inf) if edge is None else edge
    return Chunks(lane, s0, s1, edge, CellIndex.build(mid, cell))


def _junction_ends(road_map: RoadMap) -> tuple[np.ndarray, np.ndarray]:
    """(L,) bool each: some predecessor / some successor of the lane lies in a junction."""
    lanes = road_map.lanes
    n = len(lanes)
    flags = []
    for off, idx in ((lanes.pred_offsets, lanes.pred_index), (lanes.succ_offsets, lanes.succ_index)):
        owner = np.repeat(np.arange(n), np.diff(off))
        flags.append(np.bincount(owner, weights=lanes.in_junction[idx], minlength=n) > 0)
    return flags[0], flags[1]


def _near_crosswalk(road_map: RoadMap, xy: np.ndarray, clearance: float) -> np.ndarray:
    """(n,) bool: the point lies within `clearance` m of a crosswalk polygon."""
    near = np.zeros(len(xy), dtype=bool)
    if len(road_map.crosswalks) == 0 or len(xy) == 0:
        return near
    polys = [
        shapely.Polygon(road_map.crosswalks[i].astype(np.float64)) for i in range(len(road_map.crosswalks))
    ]
    hits = shapely.STRtree(polys).query(shapely.points(xy), predicate="dwithin", distance=clearance)
    near[hits[0]] = True
    return near


def _roadside(
    road_map: RoadMap,
    t: RouteTables,
    lanes: np.ndarray,
    chunk: float,
    cell: float,
    search: float,
    clearance: float,
) -> Chunks:
    """Rightmost-lane chunks whose right side is a roadside: the nearest thing to the right,
    probed at both ends and the middle, is a road edge within reach, not another lane. As where
    parking is forbidden, chunks within `clearance` m of a crosswalk or of a junction at either
    end of the lane are left out, so parked vehicles never block a crossing or a junction mouth."""
    lane, s0, s1 = _cut_lanes(t, lanes.astype(np.int64), chunk)
    pred_j, succ_j = _junction_ends(road_map)
    free = ~((pred_j[lane] & (s0 < clearance)) | (succ_j[lane] & (s1 > t.length[lane] - clearance)))
    lane, s0, s1 = lane[free], s0[free], s1[free]
    width = road_map.lanes.width[lane].astype(np.float64)
    reach = width / 2 + search
    longest = float(reach.max()) if len(reach) else 0.0
    edge = np.full(len(lane), np.inf)
    other = np.full(len(lane), np.inf)
    for s in (s0, (s0 + s1) / 2, s1):
        xy, h = t.points(lane, s)
        normal = _right_normal(h)
        edge = np.minimum(edge, _side_distance(road_map, xy, normal, longest))
        other = np.minimum(other, _lane_between(road_map, xy, normal, longest))
    # a roadside needs a road edge within reach and no other lane before it
    keep = (edge <= reach) & (other > edge) & (edge > width / 2 - 0.25)
    for s in (s0, s1):
        keep &= ~_near_crosswalk(road_map, t.points(lane, s)[0], clearance)
    mid, _ = t.points(lane[keep], (s0[keep] + s1[keep]) / 2)
    return Chunks(lane[keep], s0[keep], s1[keep], edge[keep], CellIndex.build(mid, cell))


def _crossings(road_map: RoadMap, t: RouteTables, spawn: Chunks, max_len: float, cell: float) -> Crossings:
    """Edge-to-edge crossings perpendicular to the lane at every spawn-chunk midpoint, kept when
    a road edge exists on both sides and the crossing is at most `max_len` m long."""
    xy, h = t.points(spawn.lane, (spawn.s0 + spawn.s1) / 2)
    right = _right_normal(h)
    d_right = _side_distance(road_map, xy, right, max_len)
    d_left = _side_distance(road_map, xy, -right, max_len)
    ok = np.isfinite(d_right) & np.isfinite(d_left) & (d_right + d_left <= max_len)
    start = xy[ok] - right[ok] * d_left[ok, None]
    end = xy[ok] + right[ok] * d_right[ok, None]
    return Crossings(start, end, np.zeros(int(ok.sum())), CellIndex.build((start + end) / 2, cell))


def _crosswalks(road_map: RoadMap, cell: float) -> Crossings:
    """Long axis of each crosswalk's minimum rotated rectangle, with half its short side."""
    starts, ends, halves = [], [], []
    for i in range(len(road_map.crosswalks)):
        poly = shapely.Polygon(road_map.crosswalks[i].astype(np.float64))
        rect = np.asarray(shapely.minimum_rotated_rectangle(poly).exterior.coords)[:4]
        e01, e12 = np.linalg.norm(rect[1] - rect[0]), np.linalg.norm(rect[2] - rect[1])
        if e01 < 1e-6 or e12 < 1e-6:
            continue
        if e01 >= e12:  # walk along edge 0-1: from the middle of side 3-0 to the middle of side 1-2
            a, b, short = (rect[3] + rect[0]) / 2, (rect[1] + rect[2]) / 2, e12
        else:
            a, b, short = (rect[0] + rect[1]) / 2, (rect[2] + rect[3]) / 2, e01
        starts.append(a)
        ends.append(b)
        halves.append(max(short / 2 - 0.3, 0.0))
    start = np.array(starts, dtype=np.float64).reshape(-1, 2)
    end = np.array(ends, dtype=np.float64).reshape(-1, 2)
    return Crossings(start, end, np.array(halves, dtype=np.float64), CellIndex.build((start + end) / 2, cell))


def _centres(
    t: RouteTables, spawn: Chunks, bounds: np.ndarray, size: float, stride: float, min_length: float
) -> tuple[np.ndarray, np.ndarray]:
    """Lattice of region centres and the spawnable lane length [m] inside each region (a
    summed-area table over chunk midpoints binned at stride / 2)."""
    b = stride / 2
    lo = np.asarray(bounds[:2], dtype=np.float64)
    nbx, nby = (int(np.ceil(v / b)) + 1 for v in (bounds[2:] - bounds[:2]))
    mid = spawn.cells.xy
    ix = np.clip(((mid[:, 0] - lo[0]) // b).astype(np.int64), 0, nbx - 1)
    iy = np.clip(((mid[:, 1] - lo[1]) // b).astype(np.int64), 0, nby - 1)
    hist = np.zeros((nbx, nby))
    np.add.at(hist, (ix, iy), spawn.s1 - spawn.s0)
    sat = np.zeros((nbx + 1, nby + 1))
    sat[1:, 1:] = hist.cumsum(0).cumsum(1)
    cx = np.arange(0, nbx + 1, 2)
    cy = np.arange(0, nby + 1, 2)
    gx, gy = np.meshgrid(cx, cy, indexing="ij")
    r = round(size / 2 / b)
    x0, x1 = np.clip(gx - r, 0, nbx), np.clip(gx + r, 0, nbx)
    y0, y1 = np.clip(gy - r, 0, nby), np.clip(gy + r, 0, nby)
    length = (sat[x1, y1] - sat[x0, y1] - sat[x1, y0] + sat[x0, y0]).ravel()
    centres = np.stack([lo[0] + gx.ravel() * b, lo[1] + gy.ravel() * b], axis=1)
    if len(length) == 0 or length.max() <= 0:
        return centres[:0], length[:0]
    keep = length >= min_length
    if not keep.any():
        keep = length >= 0.5 * length.max()
    return centres[keep], length[keep]


_INDEX: dict[tuple[int, tuple], tuple[weakref.ref, MapIndex]] = {}


def map_index(road_map: RoadMap, **kwargs: float) -> MapIndex:
    """The cached `MapIndex` of `road_map` for these build arguments (built on first use)."""
    key = (id(road_map), tuple(sorted(kwargs.items())))
    hit = _INDEX.get(key)
    if hit is not None and hit[0]() is road_map:
        return hit[1]
    index = MapIndex.build(road_map, **kwargs)
    _INDEX[key] = (weakref.ref(road_map, lambda _ref, k=key: _INDEX.pop(k, None)), index)
    return index
