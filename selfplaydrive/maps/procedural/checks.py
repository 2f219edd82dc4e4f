"""Validity checks for generated towns (also usable on any `MapElements` with closed curbs).

Each function returns the offending element ids, so a failing test says where to look:

- `self_intersecting_lanes`: lane centerlines that cross themselves;
- `lanes_crossing_edges`: lanes whose centerline touches or crosses a road edge;
- `open_edge_ends`: road-edge linework that does not close into loops (dangles);
- `lanes_outside_drivable`: lanes with points outside the drivable face (the region bounded
  by the road edges that contains the first lane);
- `lanes_not_strongly_connected`: lanes outside the largest strongly connected part of the
  lane graph (successors plus legal lane changes, paper section 2.1).
"""

from __future__ import annotations

import networkx as nx
import numpy as np
import shapely
from shapely.geometry import LineString

from selfplaydrive.maps.elements import MapElements


def _lines(elements: MapElements) -> list[LineString]:
    return [LineString(lane.centerline) for lane in elements.lanes]


def self_intersecting_lanes(elements: MapElements) -> list[str]:
    """Source ids of lanes whose centerline is not a simple curve."""
    lines = _lines(elements)
    return [lane.source_id for lane, line in zip(elements.lanes, lines, strict=True) if not line.is_simple]


def lanes_crossing_edges(elements: MapElements) -> list[str]:
    """Source ids of lanes whose centerline intersects any road edge."""
    edges = [LineString(e.points) for e in elements.road_edges]
    if not edges:
        return []
    tree = shapely.STRtree(edges)
    lane_idx, _ = tree.query(_lines(elements), predicate="intersects")
    return sorted({elements.lanes[i].source_id for i in lane_idx.tolist()})


def _faces(elements: MapElements) -> tuple[list, list]:
    merged = shapely.unary_union([LineString(e.points) for e in elements.road_edges])
    faces, cuts, dangles, invalid = shapely.polygonize_full([merged])
    loose = [g for part in (cuts, dangles, invalid) for g in shapely.get_parts(part)]
    return list(shapely.get_parts(faces)), loose


def open_edge_ends(elements: MapElements) -> list[np.ndarray]:
    """Road-edge pieces that belong to no closed loop (dangles, cut edges): their coordinates."""
    return [np.asarray(g.coords) for g in _faces(elements)[1]]


def lanes_outside_drivable(elements: MapElements) -> list[str]:
    """Source ids of lanes with a centerline point outside the drivable face.

    The drivable face is the polygon (from the road edges) containing the first lane's first
    point; with no such polygon every lane is reported.
    """
    faces, _ = _faces(elements)
    first = elements.lanes[0].centerline[0]
    hits = [f for f in faces if shapely.contains_xy(f, first[0], first[1])]
    if not hits:
        return [lane.source_id for lane in elements.lanes]
    face = hits[0]
    shapely.prepare(face)
    bad = []
    for lane in elements.lanes:
        pts = lane.centerline
        if not np.all(shapely.contains_xy(face, pts[:, 0], pts[:, 1])):
            bad.append(lane.source_id)
    return bad


def lanes_not_strongly_connected(elements: MapElements) -> list[str]:
    """Source ids of lanes outside the largest strongly connected component of the lane graph."""
    g = nx.DiGraph()
    g.add_nodes_from(range(len(elements.lanes)))
    for i, lane in enumerate(elements.lanes):
        g.add_edges_from((i, j) for j in lane.successors)
        if lane.left >= 0 and lane.left_change_legal:
            g.add_edge(i, lane.left)
        if lane.right >= 0 and lane.right_change_legal:
            g.add_edge(i, lane.right)
    if g.number_of_nodes() == 0:
        return []
    best = max(nx.strongly_connected_components(g), key=len)
    return [elements.lanes[i].source_id for i in range(len(elements.lanes)) if i not in best]


def check_town(elements: MapElements) -> dict[str, list]:
    """All checks; an empty list for every key means the town is valid."""
    return {
        "self_intersecting_lanes": self_intersecting_lanes(elements),
        "lanes_crossing_edges": lanes_crossing_edges(elements),
        "open_edge_ends": open_edge_ends(elements),
        "lanes_outside_drivable": lanes_outside_drivable(elements),
        "lanes_not_strongly_connected": lanes_not_strongly_connected(elements),
    }
