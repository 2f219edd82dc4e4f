"""Routing over the lane graph (paper section 2.2): random legal routes and their waypoints.

`lane_graph` builds a networkx graph for analysis tools (slow, never in the per-reset path).
Everything else works on the `RoadMap`'s CSR arrays through `RouteTables`, precomputed once per
map, and is vectorised over agents so one world reset stays cheap:

- `random_route` walks from a start lane over uniformly chosen legal successors (and, with a
  small probability, legal lane changes) until the route is long enough in time or the map
  dead-ends (real maps are cut at their border, so border lanes have no successors).
- `route_waypoints` places up to K waypoints along the route, spaced on average `spacing_s`
  seconds apart when driving at each lane's speed limit. Each gap is
  `spacing_s * U(1 - spacing_jitter, 1 + spacing_jitter)` seconds (default jitter 0.5, so
  2.5-7.5 s, mean 5 s).
"""

from __future__ import annotations

import weakref
from collections.abc import Sequence
from dataclasses import dataclass

import networkx as nx
import numpy as np

from selfplaydrive.maps.elements import LaneKind
from selfplaydrive.maps.roadmap import RoadMap

LANE_CHANGE_COST = 50.0  # [m] extra cost of a lane change edge, so routes prefer following lanes
_LANE_GAP = 1.0  # [m] gap between lanes in the flat arc-length axis of `RouteTables.gcum`
MIN_CHANGE_LENGTH = 20.0  # [m] a lane change needs at least this much lane left ahead


def lane_graph(road_map: RoadMap, lane_change_cost: float = LANE_CHANGE_COST) -> nx.DiGraph:
    """Directed graph of legal moves: successors (weight = lane length [m]) and legal lane
    changes (weight = half the lane length + `lane_change_cost`, edge attribute change=True).
    Nodes are lane indices with attribute `length` [m].
    """
    lanes = road_map.lanes
    lengths = lanes.centerlines.lengths()
    g = nx.DiGraph()
    for i in range(len(lanes)):
        g.add_node(i, length=float(lengths[i]), kind=int(lanes.kind[i]))
    for i in range(len(lanes)):
        for j in lanes.successors(i):
            g.add_edge(i, int(j), weight=float(lengths[i]), change=False)
        for nb, legal in ((lanes.left[i], lanes.left_legal[i]), (lanes.right[i], lanes.right_legal[i])):
            if nb >= 0 and legal:
                g.add_edge(i, int(nb), weight=0.5 * float(lengths[i]) + lane_change_cost, change=True)
    return g


def largest_scc_share(road_map: RoadMap, vehicle_only: bool = True) -> float:
    """Share of (vehicle) lane length inside the largest strongly connected part of the graph."""
    g = lane_graph(road_map)
    lengths = road_map.lanes.centerlines.lengths()
    keep = np.ones(len(lengths), bool)
    if vehicle_only:
        keep = road_map.lanes.kind != 2  # LaneKind.BICYCLE
        g = g.subgraph([i for i in g.nodes if keep[i]])
    best = max(nx.strongly_connected_components(g), key=lambda c: lengths[list(c)].sum())
    return float(lengths[list(best)].sum() / lengths[keep].sum())


@dataclass(frozen=True)
class RouteTables:
    """Per-map arrays for fast lane-point lookups and route walks (built once per map).

    Attributes:
        length: (L,) float64 lane length [m].
        speed: (L,) float64 lane speed limit [m/s].
        gcum: (P,) float64 flat arc-length axis: point p of lane i sits at
            base[i] + (arc length of p along lane i); strictly increasing over all points.
        base: (L,) float64 start of each lane on the `gcum` axis [m].
        heading: (P,) float64 direction [rad] of the centerline piece starting at each point
            (the last point of a lane repeats its predecessor's).
        px, py: (P,) float64 centerline point coordinates [m].
        offsets: (L + 1,) int64 centerline CSR offsets.
        succ_offsets: (L + 1,) int64; vehicle successors (bicycle lanes removed) of lane i are
            succ_index[succ_offsets[i]:succ_offsets[i + 1]].
        succ_index: (E,) int64.
        change_left: (L,) int64 legal left lane-change target or -1.
        change_right: (L,) int64 legal right lane-change target or -1.
        has_changes: Whether any legal lane change exists on the map.
    """

    length: np.ndarray
    speed: np.ndarray
    gcum: np.ndarray
    base: np.ndarray
    heading: np.ndarray
    px: np.ndarray
    py: np.ndarray
    offsets: np.ndarray
    succ_offsets: np.ndarray
    succ_index: np.ndarray
    change_left: np.ndarray
    change_right: np.ndarray
    has_changes: bool

    @classmethod
    def build(cls, road_map: RoadMap) -> RouteTables:
        """Precompute the tables of `road_map` (O(points + edges))."""
        lanes = road_map.lanes
        pts = lanes.centerlines.points.astype(np.float64)
        off = lanes.centerlines.offsets.astype(np.int64)
        n = len(lanes)
        seg = np.diff(pts, axis=0)
        seg_len = np.hypot(seg[:, 0], seg[:, 1])
        lane_of_point = np.repeat(np.arange(n), np.diff(off))
        # arc length restarting at each lane: cumulative sum minus the value at the lane start
        cum = np.concatenate([[0.0], np.cumsum(seg_len)])
        local = cum - cum[off[:-1]][lane_of_point]
        length = local[off[1:] - 1]
        base = np.concatenate([[0.0], np.cumsum(length + _LANE_GAP)[:-1]])
        heading = np.zeros(len(pts))
        heading[:-1] = np.arctan2(seg[:, 1], seg[:, 0])
        last = off[1:] - 1
        heading[last] = heading[last - 1]
        vehicle = lanes.kind != LaneKind.BICYCLE
        succ_off, succ_idx = _filtered_successors(lanes.succ_offsets, lanes.succ_index, vehicle)
        left = np.where(lanes.left_legal & (lanes.left >= 0), lanes.left, -1).astype(np.int64)
        right = np.where(lanes.right_legal & (lanes.right >= 0), lanes.right, -1).astype(np.int64)
        return cls(
            length=length,
            speed=lanes.speed_limit.astype(np.float64),
            gcum=base[lane_of_point] + local,
            base=base,
            heading=heading,
            px=pts[:, 0].copy(),
            py=pts[:, 1].copy(),
            offsets=off,
            succ_offsets=succ_off,
            succ_index=succ_idx,
            change_left=left,
            change_right=right,
            has_changes=bool(np.any(left >= 0) or np.any(right >= 0)),
        )

    def points(self, lane: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions and headings on lane centerlines.

        Args:
            lane: (n,) int lane indices.
            s: (n,) float arc length along each lane [m], clipped to [0, length].

        Returns:
            xy: (n, 2) float64 [m]; heading: (n,) float64 [rad] of the centerline there.
        """
        from selfplaydrive._sim.lanes import lane_points

        lane = np.ascontiguousarray(lane, dtype=np.int64)
        xy = np.empty((len(lane), 2))
        heading = np.empty(len(lane))
        s = np.ascontiguousarray(np.broadcast_to(s, lane.shape), dtype=np.float64)
        lane_points(
            self.gcum,
            self.px,
            self.py,
            self.heading,
            self.base,
            self.length,
            self.offsets,
            lane,
            s,
            xy,
            heading,
        )
        return xy, heading


def _filtered_successors(
    offsets: np.ndarray, index: np.ndarray, keep: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Successor CSR without the lanes where `keep` is False (vehicles never enter bike lanes)."""
    owner = np.repeat(np.arange(len(offsets) - 1), np.diff(offsets))
    ok = keep[index]
    counts = np.bincount(owner[ok], minlength=len(offsets) - 1)
    new_off = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    return new_off, index[ok].astype(np.int64)


_TABLES: dict[int, tuple[weakref.ref, RouteTables]] = {}


def route_tables(road_map: RoadMap) -> RouteTables:
    """The cached `RouteTables` of `road_map` (built on first use, dropped with the map)."""
    key = id(road_map)
    hit = _TABLES.get(key)
    if hit is not None and hit[0]() is road_map:
        return hit[1]
    tables = RouteTables.build(road_map)
    _TABLES[key] = (weakref.ref(road_map, lambda _ref, k=key: _TABLES.pop(k, None)), tables)
    return tables


@dataclass(frozen=True)
class Route:
    """A route as consecutive lane pieces; piece i drives lane `lanes[i]` from `s_start[i]` to
    `s_end[i]` [m]. A piece shorter than its lane that is followed by a piece on a neighbour
    lane is a lane change (`change[i]` True).

    Attributes:
        lanes: (n,) int64.
        s_start: (n,) float64 [m].
        s_end: (n,) float64 [m].
        change: (n,) bool, the piece ends with a lane change into the next piece's lane.
        dead_end: The route stopped because its last lane has no successor.
    """

    lanes: np.ndarray
    s_start: np.ndarray
    s_end: np.ndarray
    change: np.ndarray
    dead_end: bool

    def duration(self, speed: np.ndarray) -> float:
        """Time [s] to drive the route at the lanes' speed limits `speed` (L,) [m/s]."""
        return float(np.sum((self.s_end - self.s_start) / speed[self.lanes]))


@dataclass
class RouteBatch:
    """Routes of several agents as (A, n) piece arrays; unused pieces have zero length.

    Attributes:
        lanes: (A, n) int64 lane of each piece (-1 when unused).
        s_start, s_end: (A, n) float64 [m].
        change: (A, n) bool.
        dead_end: (A,) bool.
        t_end: (A, n) float64 [s] cumulative time at the end of each piece at the speed limit.
    """

    lanes: np.ndarray
    s_start: np.ndarray
    s_end: np.ndarray
    change: np.ndarray
    dead_end: np.ndarray
    t_end: np.ndarray

    def route(self, a: int) -> Route:
        """Route of agent `a` without unused pieces."""
        used = self.lanes[a] >= 0
        return Route(
            self.lanes[a][used],
            self.s_start[a][used],
            self.s_end[a][used],
            self.change[a][used],
            bool(self.dead_end[a]),
        )


def sample_routes(
    tables: RouteTables,
    start_lane: np.ndarray,
    start_s: np.ndarray,
    horizon_s: np.ndarray,
    rng: np.random.Generator,
    lane_change_prob: float = 0.1,
    max_pieces: int = 128,
) -> RouteBatch:
    """Random legal routes for several agents at once (Cython kernel `_sim.lanes.walk_routes`).

    Each step either follows a uniformly chosen successor to the end of the current lane, or,
    with probability `lane_change_prob` where a legal change exists, the previous step was no
    change and at least `MIN_CHANGE_LENGTH` m of lane remain, drives half of the remaining
    lane and changes lanes at the same relative position. A route stops once it lasts
    `horizon_s` seconds at the speed limit, at a dead end, or after `max_pieces` pieces.

    Args:
        tables: `route_tables(road_map)`.
        start_lane: (A,) int lane of each agent.
        start_s: (A,) float arc length [m] on the start lane.
        horizon_s: (A,) float route duration wanted [s].
        rng: Seeded generator (draws one 63-bit key; the walk's uniforms are
            `testing.spawn_reference.hash_uniforms(key, ...)`, computed on the fly).
        lane_change_prob: Probability of a lane change per step where one is legal.
        max_pieces: Upper bound on pieces per route (guards against tiny loops).

    Returns:
        The `RouteBatch`.
    """
    from selfplaydrive._sim.lanes import walk_routes

    a = len(start_lane)
    key = int(rng.integers(0, 2**63))
    out = _empty_batch(a, max_pieces)
    walk_routes(
        tables.succ_offsets,
        tables.succ_index,
        tables.change_left,
        tables.change_right,
        tables.length,
        tables.speed,
        np.ascontiguousarray(start_lane, dtype=np.int64),
        np.ascontiguousarray(start_s, dtype=np.float64),
        np.ascontiguousarray(horizon_s, dtype=np.float64),
        key,
        float(lane_change_prob),
        MIN_CHANGE_LENGTH,
        bool(lane_change_prob > 0 and tables.has_changes),
        out.lanes,
        out.s_start,
        out.s_end,
        out.change,
        out.t_end,
        out.dead_end,
    )
    used = max(int((out.lanes >= 0).sum(axis=1).max()), 1) if a else 0
    return RouteBatch(
        out.lanes[:, :used],
        out.s_start[:, :used],
        out.s_end[:, :used],
        out.change[:, :used],
        out.dead_end,
        out.t_end[:, :used],
    )


def _empty_batch(a: int, n: int) -> RouteBatch:
    return RouteBatch(
        np.full((a, n), -1, dtype=np.int64),
        np.zeros((a, n)),
        np.zeros((a, n)),
        np.zeros((a, n), dtype=bool),
        np.zeros(a, dtype=bool),
        np.zeros((a, n)),
    )


def waypoint_times(rng: np.random.Generator, a: int, k: int, spacing_s: float, jitter: float) -> np.ndarray:
    """(a, k) float64 cumulative waypoint times [s]: sums of gaps spacing_s * U(1 - j, 1 + j)."""
    gaps = spacing_s * rng.uniform(1.0 - jitter, 1.0 + jitter, (a, k))
    return np.cumsum(gaps, axis=1)


def batch_waypoints(
    tables: RouteTables, routes: RouteBatch, times: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Waypoints at the given route times (Cython kernel `_sim.lanes.route_waypoints_batch`).

    A waypoint exists where its time is within the route's duration. Where not even the first
    fits (a route that dead-ends early), the route's end becomes the single waypoint, so every
    agent has at least one.

    Args:
        tables: Route tables of the map.
        routes: (A, n) routes.
        times: (A, K) increasing waypoint times [s].

    Returns:
        waypoints: (A, K, 2) float32 [m], padded with the last valid one.
        count: (A,) int32 number of valid waypoints (1..K).
    """
    from selfplaydrive._sim.lanes import route_waypoints_batch

    a, k = times.shape
    xy = np.empty((a, k, 2), dtype=np.float32)
    count = np.empty(a, dtype=np.int32)
    c = np.ascontiguousarray
    t = tables
    route_waypoints_batch(
        c(routes.lanes), c(routes.s_start), c(routes.s_end), c(routes.t_end), c(times, dtype=np.float64),
        t.speed, t.gcum, t.px, t.py, t.base, t.length, t.offsets, xy, count,
    )  # fmt: skip
    return xy, count


def random_route(
    road_map: RoadMap,
    start_lane: int,
    rng: np.random.Generator,
    start_s: float = 0.0,
    horizon_s: float = 60.0,
    lane_change_prob: float = 0.1,
    max_pieces: int = 128,
) -> Route:
    """One random legal route from `start_lane` (see `sample_routes` for the rules).

    Args:
        road_map: The map.
        start_lane: Lane index to start on.
        rng: Seeded generator.
        start_s: Arc length [m] on the start lane.
        horizon_s: Stop once the route lasts this long [s] at the speed limits.
        lane_change_prob: Probability of a legal lane change per step.
        max_pieces: Upper bound on the number of lane pieces.

    Raises:
        ValueError: If `start_lane` is not a lane index of the map.
    """
    n = len(road_map.lanes)
    if not 0 <= int(start_lane) < n:
        raise ValueError(f"start_lane {start_lane} out of range [0, {n}) for map {road_map.name!r}")
    t = route_tables(road_map)
    batch = sample_routes(
        t,
        np.array([start_lane]),
        np.array([start_s]),
        np.array([horizon_s]),
        rng,
        lane_change_prob,
        max_pieces,
    )
    return batch.route(0)


def route_waypoints(
    road_map: RoadMap,
    route: Route | Sequence[int],
    start_s: float,
    rng: np.random.Generator,
    max_waypoints: int = 8,
    spacing_s: float = 5.0,
    spacing_jitter: float = 0.5,
) -> tuple[np.ndarray, int]:
    """Waypoints along a route, on average `spacing_s` seconds apart at the lane speed limits.

    Args:
        road_map: The map.
        route: A `Route`, or a chain of lane indices (each a successor of the one before).
        start_s: Arc length [m] on the route's first lane where the agent starts (for a `Route`
            it replaces the first piece's start).
        rng: Seeded generator (draws the gaps).
        max_waypoints: K, the most waypoints returned.
        spacing_s: Mean time gap between waypoints [s].
        spacing_jitter: Each gap is spacing_s * U(1 - jitter, 1 + jitter); 0 gives exact gaps.

    Returns:
        (K, 2) float32 waypoints [m] padded with the last valid one, and the valid count.

    Raises:
        ValueError: On an empty route, a lane index out of range or a bad spacing.
    """
    if not (spacing_s > 0 and 0.0 <= spacing_jitter < 1.0 and max_waypoints >= 1):
        raise ValueError(
            f"need spacing_s > 0, 0 <= spacing_jitter < 1, max_waypoints >= 1; got "
            f"{spacing_s}, {spacing_jitter}, {max_waypoints}"
        )
    t = route_tables(road_map)
    batch = _as_batch(t, route, start_s)
    times = waypoint_times(rng, 1, max_waypoints, spacing_s, spacing_jitter)
    wps, count = batch_waypoints(t, batch, times)
    return wps[0], int(count[0])


def _as_batch(t: RouteTables, route: Route | Sequence[int], start_s: float) -> RouteBatch:
    """A one-agent `RouteBatch` from a `Route` or a chain of lane indices."""
    lanes = route.lanes if isinstance(route, Route) else list(route)
    lanes = np.asarray(lanes, dtype=np.int64).reshape(-1)
    if len(lanes) == 0:
        raise ValueError("route has no lanes")
    if lanes.min() < 0 or lanes.max() >= len(t.length):
        raise ValueError(f"route lane indices must lie in [0, {len(t.length)}), got {lanes.tolist()}")
    if isinstance(route, Route):
        s0, s1 = route.s_start.astype(np.float64), route.s_end.astype(np.float64)
    else:
        s0, s1 = np.zeros(len(lanes)), t.length[lanes].copy()
    s0[0] = float(np.clip(start_s, 0.0, s1[0]))
    t_end = np.cumsum((s1 - s0) / t.speed[lanes])
    return RouteBatch(
        lanes[None], s0[None], s1[None], np.zeros((1, len(lanes)), bool), np.zeros(1, bool), t_end[None]
    )
