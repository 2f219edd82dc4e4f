"""Directed lanes, the lane graph and lane-change neighbours from sampled OpenDRIVE sections.

One `LaneElement` is made per drivable lane per lane section (a bidirectional lane gives two
twins). Travel direction: with right-hand traffic (the default, `rule="RHT"`) right lanes
(negative ids) follow the reference line and left lanes run against it; `rule="LHT"` swaps
this and a lane's `direction="reversed"` (OpenDRIVE 1.8) flips it again.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from selfplaydrive.maps.elements import LaneElement, LaneKind
from selfplaydrive.maps.opendrive.parse import Lane, RoadMark
from selfplaydrive.maps.opendrive.sections import SectionGeom

VEHICLE_TYPES = {
    "driving",
    "entry",
    "exit",
    "onramp",
    "offramp",
    "connectingramp",
    "bidirectional",
    "taxi",
    "hov",
}
KIND_BY_TYPE = {"bus": LaneKind.BUS, "biking": LaneKind.BICYCLE, "bicycle": LaneKind.BICYCLE}
MIN_LANE_WIDTH = 0.1  # [m] lanes never wider than this are treated as absent
MIN_SECTION_LENGTH = 0.05  # [m] shorter lane sections only pass links through (see contract)
# roadMark types a vehicle may cross; "none"/missing means no marking, which is legal
CROSSABLE_MARKS = {"", "none", "broken", "broken broken", "botts dots"}

Key = tuple[str, int, int]  # (road id, section index, lane id)


def is_drivable(lane: Lane) -> bool:
    """Vehicle, bus and bicycle lanes (sidewalks, shoulders, parking, medians are not)."""
    t = lane.type.lower()
    return t in VEHICLE_TYPES or t in KIND_BY_TYPE


@dataclass
class LaneIndex:
    """Where each OpenDRIVE lane went in `MapElements.lanes`.

    Attributes:
        by_key: (road, section, lane id) -> list of (output index, forward) where forward means
            the lane is travelled in the direction of increasing s.
        geoms: (road, section) -> the sampled section.
    """

    by_key: dict[Key, list[tuple[int, bool]]] = field(default_factory=dict)
    geoms: dict[tuple[str, int], SectionGeom] = field(default_factory=dict)
    virtual: set[int] = field(default_factory=set)


def travel_directions(lane: Lane, rule: str) -> list[bool]:
    """[forward?] for each directed copy of a lane (two for bidirectional lanes)."""
    if lane.type.lower() == "bidirectional" or lane.direction == "both":
        return [True, False]
    forward = (lane.id < 0) == (rule != "LHT")
    if lane.direction == "reversed":
        forward = not forward
    return [forward]


def _speed_at(geom: SectionGeom, lane: Lane, default: float) -> float:
    """Lane <speed> record, else the road <type><speed>, else `default`, at the section middle."""
    mid = 0.5 * (geom.s[0] + geom.s[-1])
    for s_off, v in reversed(lane.speeds):
        if geom.section.s + s_off <= mid + 1e-9:
            return v
    if lane.speeds:
        return lane.speeds[0][1]
    limit = None
    for s, v in geom.road.speeds:
        if s <= mid + 1e-9:
            limit = v
    return default if limit is None else limit


def build_lanes(geoms: Sequence[SectionGeom], default_speed: float, index: LaneIndex) -> list[LaneElement]:
    """Make the directed `LaneElement`s (no graph yet) and fill `index`."""
    out: list[LaneElement] = []
    for g in geoms:
        index.geoms[(g.road.id, g.index)] = g
        for lid in g.ordered_ids():
            lane = g.lane(lid)
            if not is_drivable(lane):
                continue
            width = g.width(lid)
            if width.max() < MIN_LANE_WIDTH:
                continue
            if lane.type.lower() == "bidirectional" and not (lane.predecessors or lane.successors):
                # an unlinked two-way lane is a centre turn lane: drivable surface, not a route
                continue
            # a degenerate section (CARLA has some of 2e-5 m) still carries lane links
            virtual = g.s[-1] - g.s[0] < MIN_SECTION_LENGTH
            t_in, t_out = g.borders[lid]
            center = g.points(0.5 * (t_in + t_out))
            directions = travel_directions(lane, g.road.rule)
            entries = []
            for forward in directions:
                out.append(
                    LaneElement(
                        centerline=center if forward else center[::-1].copy(),
                        width=float(max(width.mean(), MIN_LANE_WIDTH)),
                        speed_limit=_speed_at(g, lane, default_speed),
                        kind=KIND_BY_TYPE.get(lane.type.lower(), LaneKind.VEHICLE),
                        source_id=f"road {g.road.id}/section {g.index}/lane {lid}"
                        + ("" if forward else "/reverse") * (len(directions) > 1),
                        in_junction=g.road.junction != "-1",
                    )
                )
                entries.append((len(out) - 1, forward))
                if virtual:
                    index.virtual.add(len(out) - 1)
            if len(entries) == 2:
                out[entries[0][0]].twin, out[entries[1][0]].twin = entries[1][0], entries[0][0]
            index.by_key[(g.road.id, g.index, lid)] = entries
    return out


def connect(lanes: list[LaneElement], index: LaneIndex, a: Key, a_end: str, b: Key, b_end: str) -> None:
    """Link lane `a` at its s-end `a_end` ("start"/"end") with lane `b` at `b_end`.

    The edge goes from whichever copy leaves through the shared point to whichever enters
    through it; pairs that both leave or both enter (inconsistent files) are not linked.
    """
    for i, fi in index.by_key.get(a, []):
        i_exits = fi == (a_end == "end")
        for j, fj in index.by_key.get(b, []):
            j_enters = fj == (b_end == "start")
            if i_exits and j_enters and j not in lanes[i].successors:
                lanes[i].successors.append(j)
            elif not i_exits and not j_enters and i not in lanes[j].successors:
                lanes[j].successors.append(i)


def contract(lanes: list[LaneElement], index: LaneIndex) -> list[LaneElement]:
    """Remove the virtual lanes of degenerate sections, linking their predecessors to their
    successors, and renumber every index (successors, twins, `index.by_key`)."""
    if not index.virtual:
        return lanes
    preds: dict[int, list[int]] = {}
    for i, lane in enumerate(lanes):
        for j in lane.successors:
            preds.setdefault(j, []).append(i)
    for v in sorted(index.virtual):
        for p in preds.get(v, []):
            for s in lanes[v].successors:
                if s != v and s not in lanes[p].successors:
                    lanes[p].successors.append(s)
                    preds.setdefault(s, []).append(p)
    new_id = {}
    for i in range(len(lanes)):
        if i not in index.virtual:
            new_id[i] = len(new_id)
    kept = [lane for i, lane in enumerate(lanes) if i in new_id]
    for lane in kept:
        lane.successors = [new_id[j] for j in lane.successors if j in new_id]
        lane.twin = new_id.get(lane.twin, -1)
    index.by_key = {
        key: [(new_id[i], f) for i, f in entries if i in new_id]
        for key, entries in index.by_key.items()
        if any(i in new_id for i, _ in entries)
    }
    index.virtual = set()
    return kept


def _mark_at_section(marks: list[RoadMark], length: float) -> RoadMark | None:
    """The roadMark covering most of a section of `length` [m] (None if there is none)."""
    if not marks:
        return None
    starts = [max(0.0, m.s_offset) for m in marks] + [max(length, marks[-1].s_offset)]
    cover = [max(0.0, min(b, length) - min(a, length)) for a, b in itertools.pairwise(starts)]
    return marks[int(np.argmax(cover))]


def change_legal(mark: RoadMark | None, from_id: int, to_id: int) -> bool:
    """Whether crossing the marking from lane `from_id` into `to_id` is allowed.

    Broken or missing markings allow it, solid ones forbid it; for mixed marks ("solid
    broken") the `laneChange` attribute decides (increase / decrease / both / none).
    """
    if mark is None:
        return True
    t = " ".join(mark.type.lower().split())
    if t in CROSSABLE_MARKS:
        return True
    if t in ("solid broken", "broken solid"):
        lc = mark.lane_change.lower()
        return (
            lc == "both" or (lc == "increase" and to_id > from_id) or (lc == "decrease" and to_id < from_id)
        )
    return False


def _above(lid: int) -> int:
    """Id of the lane on the +t side of `lid` (across the centre lane for -1)."""
    return 1 if lid == -1 else lid + 1


def assign_neighbours(lanes: list[LaneElement], index: LaneIndex) -> None:
    """Left/right neighbours: adjacent drivable lanes of one section with the same direction."""
    for (rid, si), g in index.geoms.items():
        length = float(g.s[-1] - g.s[0])
        for lid in g.ordered_ids():
            up = _above(lid)
            if (rid, si, lid) not in index.by_key or (rid, si, up) not in index.by_key:
                continue
            if up > 0 and lid < 0:
                mark_lane = g.section.lanes.get(0)
            else:
                mark_lane = g.lane(lid if abs(lid) < abs(up) else up)
            mark = _mark_at_section(mark_lane.marks if mark_lane else [], length)
            for i, fi in index.by_key[(rid, si, lid)]:
                for j, fj in index.by_key[(rid, si, up)]:
                    if fi != fj or lanes[i].twin >= 0 or lanes[j].twin >= 0:
                        continue
                    # travelling +s, the +t side is on the left; travelling -s it is on the right
                    lo, hi = i, j  # lo is on the -t side of hi
                    legal_up, legal_down = change_legal(mark, lid, up), change_legal(mark, up, lid)
                    if fi:
                        lanes[lo].left, lanes[lo].left_change_legal = hi, legal_up
                        lanes[hi].right, lanes[hi].right_change_legal = lo, legal_down
                    else:
                        lanes[lo].right, lanes[lo].right_change_legal = hi, legal_up
                        lanes[hi].left, lanes[hi].left_change_legal = lo, legal_down


def snap_dangling(lanes: list[LaneElement], tol: float = 0.3, max_turn: float = 1.0) -> int:
    """Link lane ends that have no successor to lane starts that have no predecessor.

    A safety net for files with missing lane links: the end point must lie within `tol` [m]
    of the start point and the headings differ by less than `max_turn` [rad].

    Returns:
        Number of edges added.
    """
    has_pred = np.zeros(len(lanes), bool)
    for lane in lanes:
        for j in lane.successors:
            has_pred[j] = True
    starts = np.array([lane.centerline[0] for lane in lanes])
    start_dir = np.array([lane.centerline[1] - lane.centerline[0] for lane in lanes])
    added = 0
    for i, lane in enumerate(lanes):
        if lane.successors:
            continue
        end, d_end = lane.centerline[-1], lane.centerline[-1] - lane.centerline[-2]
        near = np.flatnonzero((np.hypot(*(starts - end).T) < tol) & ~has_pred)
        for j in near:
            cos = np.dot(d_end, start_dir[j]) / max(
                np.linalg.norm(d_end) * np.linalg.norm(start_dir[j]), 1e-12
            )
            if j != i and np.arccos(np.clip(cos, -1, 1)) < max_turn and lanes[j].twin != i:
                lane.successors.append(int(j))
                added += 1
    return added
