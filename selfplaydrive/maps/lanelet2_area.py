"""Road edges and junction flags of a Lanelet2 map, from the lanelet polygons (shapely).

Road edges (paper section 2.1: "the drivable area is captured by a set of lines indicating the
edges of the road") come from mapped curbstone, road_border, guard_rail, wall and fence line
strings, plus the outline of the union of all lanelets agents drive on, wherever no mapped edge
line lies within `EDGE_NEARBY` of it (maps that map only lane markings, like the CARLA towns,
get their whole outline).

A lane is flagged `in_junction` when its lanelet carries `turn_direction=left/right` or when
its area overlaps another vehicle/bus lanelet's area by more than `JUNCTION_OVERLAP` (crossing,
merging and diverging lanelets overlap, lanes of a plain road only touch along shared bounds).
"""

from __future__ import annotations

import numpy as np
import shapely
from shapely.geometry import LineString, Polygon

from selfplaydrive.maps.elements import EdgeKind, LaneKind, PolylineElement
from selfplaydrive.maps.lanelet2_geometry import dedupe
from selfplaydrive.maps.lanelet2_lanes import DirectedLane, LaneletBounds
from selfplaydrive.maps.lanelet2_osm import OsmData

EDGE_KINDS = {
    "curbstone": EdgeKind.CURB,
    "road_border": EdgeKind.ROAD_BORDER,
    "guard_rail": EdgeKind.BARRIER,
    "wall": EdgeKind.BARRIER,
    "fence": EdgeKind.BARRIER,
}
EDGE_NEARBY = 3.0  # [m] outline parts this close to a mapped edge line are covered by it
CRACK = 0.05  # [m] lanelets are grown by this much before the union to close numeric cracks
MIN_HOLE_AREA = 500.0  # [m^2] smaller holes are gaps between junction lanelets or cracks, not blocks
MIN_OUTLINE_PIECE = 1.0  # [m] shorter outline pieces are dropped
JUNCTION_OVERLAP = 1.0  # [m^2] lanelet overlap area that marks a junction
JUNCTION_TURNS = frozenset({"left", "right"})


def lanelet_polygon(b: LaneletBounds) -> shapely.Geometry:
    """Valid (possibly multi-) polygon of a lanelet's area."""
    poly = Polygon(b.polygon())
    return poly if poly.is_valid else shapely.make_valid(poly)


def mapped_edges(osm: OsmData) -> list[PolylineElement]:
    """Road edges from curbstone, road_border, guard_rail, wall and fence ways."""
    out = []
    for wid in sorted(osm.ways):
        kind = EDGE_KINDS.get(osm.ways[wid].tags.get("type", ""))
        if kind is None:
            continue
        pts = dedupe(osm.way_xy(wid))
        if len(pts) >= 2:
            out.append(PolylineElement(pts, kind, f"way {wid}"))
    return out


def _lines_of(geom: shapely.Geometry) -> list[np.ndarray]:
    parts = shapely.get_parts(shapely.line_merge(geom)) if not geom.is_empty else []
    return [
        np.asarray(p.coords)[:, :2]
        for p in parts
        if isinstance(p, LineString) and p.length >= MIN_OUTLINE_PIECE
    ]


def outline_edges(polygons: list[shapely.Geometry], edges: list[PolylineElement]) -> list[PolylineElement]:
    """Outline of the union of drivable lanelets, minus the parts near mapped edge lines."""
    if not polygons:
        return []
    area = shapely.union_all(shapely.buffer(np.asarray(polygons, dtype=object), CRACK, join_style="mitre"))
    rings = []
    for poly in shapely.get_parts(area):
        if not isinstance(poly, Polygon):
            continue
        rings.append(poly.exterior)
        rings.extend(r for r in poly.interiors if Polygon(r).area >= MIN_HOLE_AREA)
    if not rings:
        return []
    boundary = shapely.union_all(np.asarray([LineString(r.coords) for r in rings], dtype=object))
    if edges:
        covered = shapely.union_all(
            shapely.buffer(np.asarray([LineString(e.points) for e in edges], dtype=object), EDGE_NEARBY)
        )
        boundary = boundary.difference(covered)
    return [PolylineElement(p, EdgeKind.OUTLINE, f"outline {k}") for k, p in enumerate(_lines_of(boundary))]


def junction_lanelets(
    osm: OsmData, lanes: list[DirectedLane], polygons: dict[int, shapely.Geometry]
) -> set[int]:
    """Ids of the vehicle/bus lanelets inside junctions (see the module docstring)."""
    ids = sorted({ln.lanelet for ln in lanes if ln.kind in (LaneKind.VEHICLE, LaneKind.BUS)})
    flagged = {i for i in ids if osm.relations[i].tags.get("turn_direction") in JUNCTION_TURNS}
    if len(ids) < 2:
        return flagged
    geoms = np.asarray([polygons[i] for i in ids], dtype=object)
    tree = shapely.STRtree(geoms)
    a, b = tree.query(geoms, predicate="intersects")
    pair = a < b
    a, b = a[pair], b[pair]
    overlap = shapely.area(shapely.intersection(geoms[a], geoms[b]))
    hit = overlap > JUNCTION_OVERLAP
    flagged.update(ids[int(k)] for k in a[hit])
    flagged.update(ids[int(k)] for k in b[hit])
    return flagged
