"""Directed lanes and the lane graph of a Lanelet2 map (paper section 2.1: "one lane is connected
to another if a vehicle is legally allowed to drive from the first to the second").

Every usable lanelet becomes one directed lane, two (twins) when it is bidirectional. Bounds
are oriented first (`align_bounds`), then:

- successor A -> B when A's left/right bounds end where B's left/right bounds start (same node,
  or within `SUCCESSOR_TOL` for files that duplicate nodes), as in Lanelet2's routing graph;
- B is A's left neighbour when A's left bound is B's right bound, the same way in the same
  direction; the change is legal when the line's markings allow crossing it that way and both
  lanes are of the same kind (a car may not change into a bus or bicycle lane).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from selfplaydrive.errors import MapError
from selfplaydrive.maps.elements import LaneElement, LaneKind
from selfplaydrive.maps.lanelet2_geometry import align_bounds, centerline_and_width, dedupe, orient_like
from selfplaydrive.maps.lanelet2_osm import OsmData, Relation
from selfplaydrive.maps.lanelet2_rules import (
    can_cross,
    is_bidirectional,
    lane_kind,
    line_lane_change,
    parse_speed,
    sign_speed,
)

SUCCESSOR_TOL = 0.05  # [m] bound endpoints closer than this are the same point


@dataclass
class Bound:
    """One oriented lanelet bound: the way, whether it is traversed reversed, its points [m]."""

    way: int
    reversed: bool
    points: np.ndarray


@dataclass
class DirectedLane:
    """A lanelet driven in one direction, before conversion to `LaneElement`."""

    lanelet: int
    backwards: bool
    kind: LaneKind
    left: Bound
    right: Bound
    center: np.ndarray
    width: float
    speed: float
    tags: dict[str, str]
    regulatory: list[int] = field(default_factory=list)

    @property
    def source_id(self) -> str:
        return f"lanelet {self.lanelet}" + (" (reverse)" if self.backwards else "")


@dataclass
class LaneletBounds:
    """Oriented bounds of any lanelet (lanes, crosswalks, ignored subtypes alike)."""

    id: int
    left: Bound
    right: Bound

    def polygon(self) -> np.ndarray:
        """(n, 2) outline: left bound forward then right bound backward [m]."""
        return np.concatenate([self.left.points, self.right.points[::-1]])


def _bound(osm: OsmData, rel: Relation, role: str) -> tuple[int, np.ndarray]:
    ways = rel.ways(role)
    if len(ways) != 1:
        raise MapError(
            f"lanelet needs exactly one {role!r} way, got {len(ways)}", osm.path, f"lanelet {rel.id}"
        )
    pts = dedupe(osm.way_xy(ways[0]))
    if len(pts) < 2:
        raise MapError(
            f"{role} bound (way {ways[0]}) has {len(pts)} distinct point(s), expected at least 2",
            osm.path,
            f"lanelet {rel.id}",
        )
    return ways[0], pts


def oriented_bounds(osm: OsmData, rel: Relation) -> LaneletBounds:
    """Read a lanelet's left and right ways and orient them along the direction of travel."""
    lw, lp = _bound(osm, rel, "left")
    rw, rp = _bound(osm, rel, "right")
    rev_l, rev_r = align_bounds(lp, rp)
    return LaneletBounds(
        rel.id,
        Bound(lw, rev_l, lp[::-1] if rev_l else lp),
        Bound(rw, rev_r, rp[::-1] if rev_r else rp),
    )


def _reg_speed(osm: OsmData, reg_ids: list[int]) -> float | None:
    """Speed [m/s] of the first speed_limit regulatory element that states a readable value."""
    for rid in reg_ids:
        reg = osm.relations[rid]
        if reg.tags.get("subtype") != "speed_limit":
            continue
        for key in ("speed_limit", "max_speed", "sign_type"):
            v = parse_speed(reg.tags.get(key)) or sign_speed(reg.tags.get(key, ""))
            if v:
                return v
        for wid in reg.ways("refers"):
            tags = osm.ways[wid].tags
            v = parse_speed(tags.get("speed_limit")) or sign_speed(tags.get("subtype", ""))
            if v:
                return v
    return None


def build_lanes(osm: OsmData, bounds: dict[int, LaneletBounds], default_speed: float) -> list[DirectedLane]:
    """Directed lanes of every lanelet a simulated agent may use (`lane_kind` is not None)."""
    lanes: list[DirectedLane] = []
    for lid, b in bounds.items():
        rel = osm.relations[lid]
        kind = lane_kind(rel.tags)
        if kind is None:
            continue
        center, width = centerline_and_width(b.left.points, b.right.points)
        explicit = rel.ways("centerline")
        if explicit:
            pts = dedupe(osm.way_xy(explicit[0]))
            if len(pts) >= 2:
                center = orient_like(pts, center[0], center[-1])
        regs = rel.relations("regulatory_element")
        speed = parse_speed(rel.tags.get("speed_limit")) or _reg_speed(osm, regs) or default_speed
        fwd = DirectedLane(lid, False, kind, b.left, b.right, center, width, speed, rel.tags, regs)
        lanes.append(fwd)
        if is_bidirectional(rel.tags, kind):
            left = Bound(b.right.way, not b.right.reversed, b.right.points[::-1])
            right = Bound(b.left.way, not b.left.reversed, b.left.points[::-1])
            lanes.append(
                DirectedLane(lid, True, kind, left, right, center[::-1].copy(), width, speed, rel.tags, regs)
            )
    return lanes


def _successors(lanes: list[DirectedLane]) -> list[list[int]]:
    starts = np.array([np.concatenate([ln.left.points[0], ln.right.points[0]]) for ln in lanes])
    ends = np.array([np.concatenate([ln.left.points[-1], ln.right.points[-1]]) for ln in lanes])
    tree = cKDTree(starts)
    found = tree.query_ball_point(ends, r=SUCCESSOR_TOL * np.sqrt(2.0))
    succ: list[list[int]] = []
    for i, cand in enumerate(found):
        ln = lanes[i]
        # a lane never continues into its own twin (that would be a U-turn on the same geometry)
        succ.append(sorted(j for j in cand if j != i and lanes[j].lanelet != ln.lanelet))
    return succ


def to_elements(osm: OsmData, lanes: list[DirectedLane]) -> list[LaneElement]:
    """Convert directed lanes to `LaneElement`s with successors, neighbours and twins."""
    if not lanes:
        return []
    succ = _successors(lanes)
    by_right = {(ln.right.way, ln.right.reversed): i for i, ln in enumerate(lanes)}
    by_left = {(ln.left.way, ln.left.reversed): i for i, ln in enumerate(lanes)}
    twin_of = {(ln.lanelet, ln.backwards): i for i, ln in enumerate(lanes)}
    out = []
    for i, ln in enumerate(lanes):
        left = by_right.get((ln.left.way, ln.left.reversed), -1)
        right = by_left.get((ln.right.way, ln.right.reversed), -1)
        left_legal = (
            left >= 0
            and lanes[left].kind == ln.kind
            and can_cross(line_lane_change(osm.ways[ln.left.way].tags), ln.left.reversed, to_left=True)
        )
        right_legal = (
            right >= 0
            and lanes[right].kind == ln.kind
            and can_cross(line_lane_change(osm.ways[ln.right.way].tags), ln.right.reversed, to_left=False)
        )
        out.append(
            LaneElement(
                centerline=ln.center,
                width=ln.width,
                speed_limit=ln.speed,
                kind=ln.kind,
                source_id=ln.source_id,
                successors=succ[i],
                left=left,
                left_change_legal=bool(left_legal),
                right=right,
                right_change_legal=bool(right_legal),
                twin=twin_of.get((ln.lanelet, not ln.backwards), -1),
            )
        )
    return out
