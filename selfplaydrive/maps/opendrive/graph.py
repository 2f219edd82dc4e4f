"""Lane-graph edges from OpenDRIVE links: lane sections, road links and junction connections.

Each OpenDRIVE link joins one lane end to another; `lanes.connect` turns it into a directed
successor edge according to the travel direction of both lanes (paper section 2.2 routes over
these edges).
"""

from __future__ import annotations

import numpy as np

from selfplaydrive.maps.elements import LaneElement
from selfplaydrive.maps.opendrive.geometry import ReferenceLine
from selfplaydrive.maps.opendrive.lanes import LaneIndex, connect
from selfplaydrive.maps.opendrive.parse import OdrMap, Road, RoadLink


def _section_at(road: Road, end: str) -> int:
    return 0 if end == "start" else len(road.sections) - 1


def _end_xy(ref: ReferenceLine, road: Road, end: str) -> np.ndarray:
    x, y, _ = ref.evaluate(np.array([0.0 if end == "start" else road.length]))
    return np.array([x[0], y[0]])


def _contact(odr: OdrMap, refs: dict[str, ReferenceLine], road: Road, road_end: str, link: RoadLink) -> str:
    """The other road's end touching `road` at `road_end`: the link's contactPoint, else nearest end."""
    if link.contact_point in ("start", "end"):
        return link.contact_point
    other = odr.roads[link.element_id]
    p = _end_xy(refs[road.id], road, road_end)
    d = {e: np.hypot(*(p - _end_xy(refs[other.id], other, e))) for e in ("start", "end")}
    return min(d, key=d.get)


def _within_road(lanes: list[LaneElement], index: LaneIndex, road: Road) -> None:
    for k in range(len(road.sections) - 1):
        here, nxt = road.sections[k], road.sections[k + 1]
        for lid, lane in here.lanes.items():
            for m in lane.successors:
                connect(lanes, index, (road.id, k, lid), "end", (road.id, k + 1, m), "start")
            # files that omit lane links on both sides: keep the lane id across the boundary
            other = nxt.lanes.get(lid)
            if not lane.has_link and other is not None and not other.has_link:
                connect(lanes, index, (road.id, k, lid), "end", (road.id, k + 1, lid), "start")
        for lid, lane in nxt.lanes.items():
            for m in lane.predecessors:
                connect(lanes, index, (road.id, k, m), "end", (road.id, k + 1, lid), "start")


def _road_links(
    lanes: list[LaneElement], index: LaneIndex, odr: OdrMap, refs: dict[str, ReferenceLine], road: Road
) -> None:
    for road_end, link in (("start", road.predecessor), ("end", road.successor)):
        if link is None or link.element_type != "road" or link.element_id not in odr.roads:
            continue
        other = odr.roads[link.element_id]
        cp = _contact(odr, refs, road, road_end, link)
        k, ko = _section_at(road, road_end), _section_at(other, cp)
        for lid, lane in road.sections[k].lanes.items():
            for m in lane.predecessors if road_end == "start" else lane.successors:
                connect(lanes, index, (road.id, k, lid), road_end, (other.id, ko, m), cp)


def _incoming_end(
    odr: OdrMap, refs: dict[str, ReferenceLine], incoming: Road, junction: str, conn_road: Road, cp: str
) -> str:
    """Which end of the incoming road touches the junction."""
    ends = [
        e
        for e, lk in (("start", incoming.predecessor), ("end", incoming.successor))
        if lk is not None and lk.element_type == "junction" and lk.element_id == junction
    ]
    if len(ends) == 1:
        return ends[0]
    p = _end_xy(refs[conn_road.id], conn_road, cp)
    d = {e: np.hypot(*(p - _end_xy(refs[incoming.id], incoming, e))) for e in ("start", "end")}
    return min(d, key=d.get)


def _junctions(
    lanes: list[LaneElement], index: LaneIndex, odr: OdrMap, refs: dict[str, ReferenceLine]
) -> None:
    for jid, conns in odr.junctions.items():
        for c in conns:
            if c.incoming not in odr.roads or c.connecting not in odr.roads:
                continue
            inc, con = odr.roads[c.incoming], odr.roads[c.connecting]
            cp = c.contact_point if c.contact_point in ("start", "end") else "start"
            inc_end = _incoming_end(odr, refs, inc, jid, con, cp)
            ki, kc = _section_at(inc, inc_end), _section_at(con, cp)
            for a, b in c.lane_links:
                connect(lanes, index, (inc.id, ki, a), inc_end, (con.id, kc, b), cp)


def link_lanes(
    lanes: list[LaneElement], index: LaneIndex, odr: OdrMap, refs: dict[str, ReferenceLine]
) -> None:
    """Add successor edges for every lane-section, road and junction link of the map."""
    for road in odr.roads.values():
        _within_road(lanes, index, road)
        _road_links(lanes, index, odr, refs, road)
    _junctions(lanes, index, odr, refs)
