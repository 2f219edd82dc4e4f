"""Street graph of a procedural town: a jittered grid with some minor streets removed.

Nodes are junctions (grid crossings), roads are two-way street segments between two nodes.
Main roads run along every `main_road_every`-th interior grid line and stay straight; minor
streets may be bent and removed. Removal keeps every node at degree >= 3 (the four grid
corners keep 2) and keeps the street graph strongly connected for a driver who never makes a
U-turn, so the lane graph built on top has no dead ends.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import networkx as nx
import numpy as np

from selfplaydrive.maps.procedural.geometry import Path
from selfplaydrive.maps.procedural.params import TownParams

# irregularity 1 moves nodes by up to this share of the grid spacing (each axis)
JITTER_SHARE = 0.15
# irregularity 1 bends streets sideways by up to this share of their length
BEND_SHARE = 0.06
# street removal checks strong connectivity about this many times (once per batch)
REMOVAL_BATCHES = 8


@dataclass
class Road:
    """A two-way street between nodes u and v.

    Attributes:
        index: Position in `Network.roads`.
        u, v: Node indices; direction 0 runs u -> v, direction 1 runs v -> u.
        path: Reference line from node u's centre to node v's centre (the line between the
            two directions of travel).
        main: Main road (wider, faster, turn pockets) or minor street.
        lanes: Lanes per direction.
        lane_width: [m].
        speed_limit: [m/s].
    """

    index: int
    u: int
    v: int
    path: Path
    main: bool
    lanes: int
    lane_width: float
    speed_limit: float

    def end_node(self, direction: int) -> int:
        """Node a vehicle travelling in `direction` drives towards."""
        return self.v if direction == 0 else self.u

    def start_node(self, direction: int) -> int:
        """Node a vehicle travelling in `direction` comes from."""
        return self.u if direction == 0 else self.v


@dataclass
class Network:
    """Nodes (positions [m]) and roads, plus each node's incident roads."""

    nodes: np.ndarray
    roads: list[Road]
    node_roads: list[list[int]]


def _grid_edges(n: int, main_lines: set[int]) -> list[tuple[int, int, bool, bool]]:
    """(node a, node b, main, boundary) for every grid edge; node id = i * (n + 1) + j."""
    edges = []
    for i in range(n + 1):
        for j in range(n + 1):
            a = i * (n + 1) + j
            if i < n:  # along x, on row j
                edges.append((a, a + n + 1, j in main_lines, j in (0, n)))
            if j < n:  # along y, on column i
                edges.append((a, a + 1, i in main_lines, i in (0, n)))
    return edges


def _no_uturn_strongly_connected(num_nodes: int, edges: list[tuple[int, int]]) -> bool:
    """Whether every directed street can reach every other without U-turns (half-edge graph)."""
    incident: list[list[int]] = [[] for _ in range(num_nodes)]
    for k, (a, b) in enumerate(edges):
        incident[a].append(k)
        incident[b].append(k)
    g = nx.DiGraph()
    for k, (a, b) in enumerate(edges):
        for d, end in ((0, b), (1, a)):
            g.add_node((k, d))
            for k2 in incident[end]:
                if k2 != k:
                    g.add_edge((k, d), (k2, 0 if edges[k2][0] == end else 1))
    return g.number_of_nodes() > 0 and nx.is_strongly_connected(g)


def _remove_streets(
    rng: np.random.Generator, num_nodes: int, edges: list[tuple[int, int, bool, bool]], share: float
) -> list[tuple[int, int, bool, bool]]:
    """Drop `share` of the removable minor streets, keeping degrees >= 3 and strong connectivity.

    Candidates are taken in random order; connectivity is checked once per batch of
    removals (about `REMOVAL_BATCHES` checks in all, so big towns stay fast) and edge by edge
    only for a batch that fails.
    """
    degree = np.zeros(num_nodes, dtype=np.int64)
    for a, b, _, _ in edges:
        degree[a] += 1
        degree[b] += 1
    cand = [k for k, (_, _, main, boundary) in enumerate(edges) if not main and not boundary]
    target = round(share * len(cand))
    batch_size = max(1, math.ceil(target / REMOVAL_BATCHES))
    removed: set[int] = set()

    def connected_without(extra: set[int]) -> bool:
        kept = [(x[0], x[1]) for i, x in enumerate(edges) if i not in removed and i not in extra]
        return _no_uturn_strongly_connected(num_nodes, kept)

    def commit(batch: list[int]) -> None:
        if connected_without(set(batch)):
            removed.update(batch)
            return
        for e in batch:  # undo, then retry one by one
            degree[edges[e][0]] += 1
            degree[edges[e][1]] += 1
        for e in batch:
            a, b = edges[e][0], edges[e][1]
            if degree[a] > 3 and degree[b] > 3 and connected_without({e}):
                removed.add(e)
                degree[a] -= 1
                degree[b] -= 1

    batch: list[int] = []
    for k in rng.permutation(len(cand)):
        if len(removed) + len(batch) >= target:
            break
        e = cand[int(k)]
        a, b = edges[e][0], edges[e][1]
        if degree[a] <= 3 or degree[b] <= 3:
            continue
        batch.append(e)
        degree[a] -= 1
        degree[b] -= 1
        if len(batch) == batch_size:
            commit(batch)
            batch = []
    if batch:
        commit(batch)
    return [x for i, x in enumerate(edges) if i not in removed]


def _road_path(pa: np.ndarray, pb: np.ndarray, bend: float, step: float) -> Path:
    """Straight line, or a sideways sin^2 bump of amplitude `bend` [m] (ends keep the chord direction)."""
    if bend == 0.0:
        return Path(np.stack([pa, pb]))
    chord = pb - pa
    length = float(np.hypot(*chord))
    n = max(8, math.ceil(length / step)) + 1
    t = np.linspace(0.0, 1.0, n)[:, None]
    left = np.array([-chord[1], chord[0]]) / length
    return Path(pa + t * chord + bend * np.sin(np.pi * t) ** 2 * left)


def build_network(rng: np.random.Generator, p: TownParams) -> Network:
    """Jittered grid street graph (see module docstring).

    Args:
        rng: The town's only random generator.
        p: Validated parameters.
    """
    n = max(2, round(p.size / p.block_size))
    spacing = p.size / n
    ij = np.array([(i, j) for i in range(n + 1) for j in range(n + 1)], dtype=np.float64)
    jitter = rng.uniform(-1.0, 1.0, size=ij.shape) * JITTER_SHARE * spacing * p.irregularity
    nodes = ij * spacing + jitter
    mid = n // 2
    main_lines = {k for k in range(1, n) if (k - mid) % p.main_road_every == 0}
    edges = _grid_edges(n, main_lines)
    share = p.removed_street_share * (1.0 + 2.0 * p.irregularity) / 3.0
    edges = _remove_streets(rng, len(nodes), edges, share)
    bends = rng.uniform(-1.0, 1.0, size=len(edges)) * BEND_SHARE * p.irregularity
    bent = rng.uniform(0.0, 1.0, size=len(edges)) < p.irregularity
    zone30 = rng.uniform(0.0, 1.0, size=len(edges)) < p.zone30_share
    roads: list[Road] = []
    node_roads: list[list[int]] = [[] for _ in range(len(nodes))]
    for k, (a, b, main, _) in enumerate(edges):
        length = float(np.hypot(*(nodes[b] - nodes[a])))
        bend = 0.0 if main or not bent[k] else float(bends[k]) * length
        if main:
            lanes, width, speed = p.lanes_per_direction, p.lane_width, p.main_speed_limit
        else:
            speed = p.zone30_speed_limit if zone30[k] else p.minor_speed_limit
            lanes, width = p.minor_lanes_per_direction, p.minor_lane_width
        path = _road_path(nodes[a], nodes[b], bend, p.sample_step)
        roads.append(Road(k, a, b, path, bool(main), int(lanes), float(width), float(speed)))
        node_roads[a].append(k)
        node_roads[b].append(k)
    return Network(nodes=nodes, roads=roads, node_roads=node_roads)
