"""Traffic lights, stop/yield lines and crosswalks of a Lanelet2 map (paper section 2.1).

- A `traffic_light` regulatory element is one signal group; each of its `ref_line` ways is a
  traffic-light stop line controlling the lanes whose lanelet references the element. Without a
  ref_line the stop line is the end of each referencing lanelet (Lanelet2's rule).
- `ref_line`s of `right_of_way` (lanes in role "yield") and `traffic_sign` elements, `stop_line`
  ways not used by a traffic light, and `yield` line ways become stop lines; the paper treats
  them all as yield lines, `StopKind` keeps what the sign said.
- `crosswalk` lanelets become crosswalk polygons.
"""

from __future__ import annotations

import numpy as np
import shapely
from shapely.geometry import LineString, Point

from selfplaydrive.maps.elements import CrosswalkElement, StopKind, StopLineElement, TrafficLightElement
from selfplaydrive.maps.lanelet2_geometry import dedupe
from selfplaydrive.maps.lanelet2_lanes import DirectedLane, LaneletBounds
from selfplaydrive.maps.lanelet2_osm import OsmData, Relation

STOP_SIGN_SUBTYPES = frozenset({"stop_sign", "stop", "de206", "ee221", "us_r1-1"})
LANE_END_TOL = 3.0  # [m] a lane ends at a stop line when its end is this close
MAX_ALIGN_COS = 0.8  # a lane crossing a stop line must cross it at more than ~37 degrees


def _line(osm: OsmData, way: int) -> np.ndarray | None:
    pts = dedupe(osm.way_xy(way))
    return pts if len(pts) >= 2 else None


def _referencing(osm: OsmData, lanes: list[DirectedLane]) -> dict[int, list[int]]:
    """Regulatory element id -> indices of the directed lanes whose lanelet references it."""
    refs: dict[int, list[int]] = {}
    for i, ln in enumerate(lanes):
        for rid in ln.regulatory:
            refs.setdefault(rid, []).append(i)
    return refs


def _approaching(lanes: list[DirectedLane], idx: list[int], line: np.ndarray) -> list[int]:
    """The lanes `idx` a line applies to: all of them, except that of two twins (bidirectional
    lanelet) only the one driving towards the line (end nearer than start) is kept."""
    geom = LineString(line)
    lanelets = [lanes[i].lanelet for i in idx]
    keep = []
    for i in idx:
        c = lanes[i].center
        if lanelets.count(lanes[i].lanelet) < 2 or geom.distance(Point(c[-1])) < geom.distance(Point(c[0])):
            keep.append(i)
    return keep


def _tangent_at_line(c: np.ndarray, geom: LineString) -> np.ndarray | None:
    """Direction of centerline `c` where it meets the stop line, or None if it does not."""
    if geom.distance(Point(c[-1])) <= LANE_END_TOL:
        return c[-1] - c[-2]
    cl = LineString(c)
    if geom.distance(Point(c[0])) <= LANE_END_TOL or not cl.intersects(geom):
        return None
    s = cl.project(cl.intersection(geom).representative_point())
    a = np.asarray(cl.interpolate(max(s - 1.0, 0.0)).coords[0])
    b = np.asarray(cl.interpolate(min(s + 1.0, cl.length)).coords[0])
    return b - a


def lanes_at_line(lanes: list[DirectedLane], tree: shapely.STRtree, line: np.ndarray) -> list[int]:
    """Lanes a stop line applies to, found geometrically: lanes that end at the line or cross it
    (not at their start) at a steep enough angle."""
    geom = LineString(line)
    d = line[-1] - line[0]
    d = d / max(float(np.hypot(*d)), 1e-9)
    out = []
    for i in tree.query(geom, predicate="dwithin", distance=LANE_END_TOL):
        t = _tangent_at_line(lanes[int(i)].center, geom)
        if t is None:
            continue
        n = float(np.hypot(*t))
        if n > 1e-9 and abs(float(np.dot(t / n, d))) < MAX_ALIGN_COS:
            out.append(int(i))
    return sorted(out)


def traffic_lights(
    osm: OsmData, lanes: list[DirectedLane], tree: shapely.STRtree
) -> tuple[list[TrafficLightElement], set[int]]:
    """Traffic-light stop lines, one signal group per regulatory element; also returns the ids
    of the ways used as their stop lines."""
    refs = _referencing(osm, lanes)
    out: list[TrafficLightElement] = []
    used: set[int] = set()
    group = 0
    for reg in sorted(osm.relations.values(), key=lambda r: r.id):
        if reg.tags.get("type") != "regulatory_element" or reg.tags.get("subtype") != "traffic_light":
            continue
        lines = [(w, _line(osm, w)) for w in reg.ways("ref_line")]
        lines = [(w, p) for w, p in lines if p is not None]
        made = False
        if lines:
            for w, pts in lines:
                idx = _approaching(lanes, refs.get(reg.id, []), pts) or lanes_at_line(lanes, tree, pts)
                out.append(TrafficLightElement(pts, group, idx, f"regulatory_element {reg.id} ref_line {w}"))
                used.add(w)
                made = True
        else:
            # no ref_line: vehicles stop at the end of each lanelet that references the light
            for i in refs.get(reg.id, []):
                ln = lanes[i]
                pts = dedupe(np.array([ln.left.points[-1], ln.right.points[-1]]))
                if len(pts) == 2:
                    out.append(
                        TrafficLightElement(pts, group, [i], f"regulatory_element {reg.id} {ln.source_id}")
                    )
                    made = True
        group += int(made)
    return out, used


def _sign_kind(osm: OsmData, reg: Relation) -> StopKind:
    signs = {osm.ways[w].tags.get("subtype", "") for w in reg.ways("refers")}
    signs |= {osm.ways[w].tags.get("type", "") for w in reg.ways("refers")}
    return StopKind.STOP if signs & STOP_SIGN_SUBTYPES else StopKind.YIELD


def stop_lines(
    osm: OsmData, lanes: list[DirectedLane], tree: shapely.STRtree, light_ways: set[int]
) -> list[StopLineElement]:
    """Stop and yield lines that are not traffic-light stop lines."""
    refs = _referencing(osm, lanes)
    lane_of = {}
    for i, ln in enumerate(lanes):
        lane_of.setdefault(ln.lanelet, []).append(i)
    found: dict[int, StopLineElement] = {}
    for reg in sorted(osm.relations.values(), key=lambda r: r.id):
        sub = reg.tags.get("subtype")
        if reg.tags.get("type") != "regulatory_element" or sub not in (
            "right_of_way",
            "traffic_sign",
            "all_way_stop",
        ):
            continue
        if sub == "right_of_way":
            yielding = [i for lid in reg.relations("yield") for i in lane_of.get(lid, [])]
            kind = StopKind.YIELD
        else:
            yielding = refs.get(reg.id, [])
            kind = _sign_kind(osm, reg) if sub == "traffic_sign" else StopKind.STOP
        for w in reg.ways("ref_line"):
            pts = _line(osm, w)
            if w in light_ways or pts is None:
                continue
            idx = _approaching(lanes, yielding, pts) or lanes_at_line(lanes, tree, pts)
            if w in found:
                found[w].lanes = sorted(set(found[w].lanes) | set(idx))
            else:
                found[w] = StopLineElement(pts, kind, idx, f"regulatory_element {reg.id} ref_line {w}")
    for w in sorted(osm.ways):
        line_type = osm.ways[w].tags.get("type")
        if line_type not in ("stop_line", "yield") or w in light_ways or w in found:
            continue
        pts = _line(osm, w)
        if pts is not None:
            kind = StopKind.YIELD if line_type == "yield" else StopKind.STOP
            found[w] = StopLineElement(pts, kind, lanes_at_line(lanes, tree, pts), f"way {w}")
    return list(found.values())


def crosswalks(osm: OsmData, bounds: dict[int, LaneletBounds]) -> list[CrosswalkElement]:
    """Outline polygons of the crosswalk lanelets."""
    out = []
    for lid, b in bounds.items():
        if osm.relations[lid].tags.get("subtype") != "crosswalk":
            continue
        poly = dedupe(b.polygon())
        if len(poly) > 3 and np.hypot(*(poly[0] - poly[-1])) < 1e-6:
            poly = poly[:-1]
        out.append(CrosswalkElement(poly, f"lanelet {lid}"))
    return out
