"""Road edges: where the drivable surface ends (paper section 2.1, "lines indicating the edges").

Outside junctions an edge is the outer border of each run of adjacent drivable lanes in a lane
section (so a median between two carriageways gives two edges, a shoulder or sidewalk is
outside the edge). Inside a junction the borders of the connecting roads would cut across the
intersection, so the junction's edge is instead the outline of the union of all its connecting
lanes, minus the "mouths" where the incoming and outgoing roads attach. Holes of that union are
not edges: in most junctions they are gaps between turning lanes, not kerbs.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import shapely
from shapely.geometry import LineString, Polygon

from selfplaydrive.maps.elements import EdgeKind, PolylineElement
from selfplaydrive.maps.opendrive.lanes import MIN_LANE_WIDTH, LaneIndex, is_drivable
from selfplaydrive.maps.opendrive.parse import OdrMap
from selfplaydrive.maps.opendrive.sections import SectionGeom

MOUTH_CLEARANCE = 0.3  # [m] junction outline within this distance of a road mouth is dropped
MIN_EDGE_LENGTH = 0.5  # [m]
_CLOSE_GAPS = 0.1  # [m] buffer that closes hairline gaps between adjacent lane polygons


def _runs(g: SectionGeom) -> list[tuple[int, int]]:
    """Runs of adjacent drivable lanes as (top lane id, bottom lane id), +t side first.

    Non-drivable lanes narrower than MIN_LANE_WIDTH everywhere do not break a run.
    """
    runs, top, bottom = [], None, None
    for lid in g.ordered_ids():
        lane = g.lane(lid)
        if is_drivable(lane) and g.width(lid).max() >= MIN_LANE_WIDTH:
            top = lid if top is None else top
            bottom = lid
        elif g.width(lid).max() >= MIN_LANE_WIDTH and top is not None:
            runs.append((top, bottom))
            top = bottom = None
    if top is not None:
        runs.append((top, bottom))
    return runs


def road_edges(geoms: Sequence[SectionGeom]) -> list[PolylineElement]:
    """Edges of all lane sections outside junctions."""
    out = []
    for g in geoms:
        if g.road.junction != "-1" or len(g.s) < 2:
            continue
        for top, bottom in _runs(g):
            for lid, t in ((top, g.upper_lower(top)[0]), (bottom, g.upper_lower(bottom)[1])):
                pts = g.points(t)
                if np.sum(np.hypot(*np.diff(pts, axis=0).T)) >= MIN_EDGE_LENGTH:
                    out.append(
                        PolylineElement(
                            pts, EdgeKind.OUTLINE, f"road {g.road.id}/section {g.index}/lane {lid}"
                        )
                    )
    return out


def _lane_polygons_and_mouths(geoms: Sequence[SectionGeom]) -> tuple[list[Polygon], list[LineString]]:
    polys, mouths = [], []
    for g in geoms:
        drivable = [
            lid
            for lid in g.ordered_ids()
            if is_drivable(g.lane(lid)) and g.width(lid).max() >= MIN_LANE_WIDTH
        ]
        for lid in drivable:
            up, low = g.upper_lower(lid)
            ring = np.concatenate([g.points(up), g.points(low)[::-1]])
            poly = Polygon(ring)
            if not poly.is_valid:
                poly = shapely.make_valid(poly)
            polys.append(poly)
        if drivable:
            t_hi = g.upper_lower(drivable[0])[0]
            t_lo = g.upper_lower(drivable[-1])[1]
            for k in (0, -1):
                a, b = g.points(t_hi)[k], g.points(t_lo)[k]
                if np.hypot(*(a - b)) > 1e-6:
                    mouths.append(LineString([a, b]))
    return polys, mouths


def _pieces(geom: shapely.Geometry) -> list[np.ndarray]:
    if geom.is_empty:
        return []
    merged = shapely.line_merge(geom) if geom.geom_type == "MultiLineString" else geom
    parts = getattr(merged, "geoms", [merged])
    return [
        np.asarray(p.coords)[:, :2]
        for p in parts
        if p.geom_type == "LineString" and p.length >= MIN_EDGE_LENGTH
    ]


def junction_edges(odr: OdrMap, index: LaneIndex) -> list[PolylineElement]:
    """Outline of each junction's drivable area, open at the mouths of the attached roads."""
    by_junction: dict[str, list[SectionGeom]] = {}
    for g in index.geoms.values():
        if g.road.junction != "-1":
            by_junction.setdefault(g.road.junction, []).append(g)
    out = []
    for jid, geoms in sorted(by_junction.items()):
        polys, mouths = _lane_polygons_and_mouths(geoms)
        if not polys:
            continue
        area = shapely.union_all([p.buffer(_CLOSE_GAPS) for p in polys]).buffer(-_CLOSE_GAPS)
        rings = [p.exterior for p in getattr(area, "geoms", [area]) if p.geom_type == "Polygon"]
        if not rings:
            continue
        outline = shapely.union_all(rings)
        if mouths:
            outline = outline.difference(shapely.union_all(mouths).buffer(MOUTH_CLEARANCE, cap_style="flat"))
        for k, pts in enumerate(_pieces(outline)):
            out.append(PolylineElement(pts, EdgeKind.OUTLINE, f"junction {jid}/outline {k}"))
    return out
