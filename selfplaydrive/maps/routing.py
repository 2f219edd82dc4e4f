"""Routing over the lane graph (paper section 2.2): networkx graph, random legal routes, waypoints."""

from __future__ import annotations

import networkx as nx
import numpy as np

from selfplaydrive.maps.roadmap import RoadMap

LANE_CHANGE_COST = 50.0  # [m] extra cost of a lane change edge, so routes prefer following lanes


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
