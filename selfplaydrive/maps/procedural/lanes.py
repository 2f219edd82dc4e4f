"""Lanes, road edges, crosswalks and stop-line positions along the roads of a town.

Each road direction is cut into segments (right-hand traffic, lanes listed left to right):

- A: from the junction it leaves to where the next approach begins; dashed lines (lane
  changes legal).
- B1 (only with turn pockets): the pocket lanes branch off the leftmost / rightmost through
  lane (they are successors of it) and widen to full width over `taper_length`; dashed lines.
- B2: the last `solid_line_length` before the stop line; solid lines (no lane changes), so a
  vehicle must be in a lane serving its turn before it gets there (paper section 4.3, "Turning
  from the Correct Lane").

A left pocket keeps the position of the leftmost through lane, which moves one lane width to
the right together with the lanes beside it; a right pocket opens to the right. The road
edge follows the width of the lanes plus `shoulder`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from selfplaydrive.maps.elements import CrosswalkElement, PolylineElement
from selfplaydrive.maps.procedural.geometry import Path, right_normal, smoothstep
from selfplaydrive.maps.procedural.intersections import MIN_BODY
from selfplaydrive.maps.procedural.layout import Arm, DirLanes, TownSink
from selfplaydrive.maps.procedural.network import Network, Road
from selfplaydrive.maps.procedural.params import TownParams

MIN_POCKET = 20.0  # [m] shorter pockets are dropped
MIN_SOLID = 3.0  # [m] shorter solid-line segments are dropped
DENSE_STEP = 2.5  # [m] sampling inside tapers


@dataclass
class DirPlan:
    """Where one road direction's lanes start and end and how its approach is laid out.

    All distances are arc lengths [m] along the direction's own path.
    """

    path: Path
    s_start: float
    s_end: float
    lanes: int
    width: float
    left: bool
    right: bool
    pocket: float  # pocket length (0 without pockets)
    taper: float
    solid: float

    def fractions(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Opened share (0..1) of the left and right pocket at arc lengths s."""
        grow = smoothstep((s - (self.s_end - self.pocket)) / self.taper) if self.pocket > 0 else 0.0 * s
        return grow * float(self.left), grow * float(self.right)

    def half_width(self, s: np.ndarray, shoulder: float) -> np.ndarray:
        """Distance [m] from the reference line to this direction's road edge."""
        fl, fr = self.fractions(s)
        return (self.lanes + fl + fr) * self.width + shoulder

    def offset(self, role: str, i: int, s: np.ndarray) -> np.ndarray:
        """Right offset [m] of lane `role` ("L", "T" number i, "R") at arc lengths s."""
        fl, fr = self.fractions(s)
        if role == "L":
            return np.full_like(s, 0.5 * self.width)
        if role == "T":
            return (fl + i + 0.5) * self.width
        return (fl + self.lanes - 0.5 + fr) * self.width

    def dense(self) -> tuple[float, ...]:
        """Extra sample positions over the taper, both ends included.

        Lanes and road edges sample the taper at the same positions, so their straight
        pieces keep the same order side by side and never cross.
        """
        if self.pocket <= 0:
            return ()
        s0 = self.s_end - self.pocket
        k = max(4, math.ceil(self.taper / DENSE_STEP))
        return tuple(np.linspace(s0, s0 + self.taper, k + 1).tolist())


def plan_direction(road: Road, d: int, arm_start: Arm, arm_end: Arm, p: TownParams) -> DirPlan:
    """Lay out direction d of `road`; drops pockets that do not fit and updates `arm_end`."""
    path = road.path if d == 0 else road.path.reversed()
    s0, s1 = arm_start.r_lane, path.length - arm_end.r_lane
    body = s1 - s0
    if body < MIN_BODY - 1e-6:  # fit_street guarantees the room; this guards regressions
        raise AssertionError(
            f"road {road.index} direction {d}: junctions overlap (only {body:.1f} m of lane)"
        )
    # the other direction's pocket widens the other side of the road: up to 60 % of the body each
    pocket = min(p.turn_lane_length, 0.6 * body) if (arm_end.left_pocket or arm_end.right_pocket) else 0.0
    if pocket < MIN_POCKET:
        pocket = 0.0
        arm_end.left_pocket = arm_end.right_pocket = False
    taper = min(p.taper_length, 0.5 * pocket) if pocket else p.taper_length
    solid = min(p.solid_line_length, pocket - taper) if pocket else min(p.solid_line_length, 0.3 * body)
    if solid < MIN_SOLID:
        solid = 0.0
    return DirPlan(
        path,
        s0,
        s1,
        road.lanes,
        road.lane_width,
        arm_end.left_pocket,
        arm_end.right_pocket,
        pocket,
        taper,
        solid,
    )


def _segments(plan: DirPlan) -> list[tuple[float, float, list[str], bool]]:
    """(s0, s1, roles, lane changes legal) of each segment, in driving order."""
    through = ["T"] * plan.lanes
    full = ["L"] * plan.left + through + ["R"] * plan.right
    cuts: list[tuple[float, float, list[str], bool]] = []
    s = plan.s_start
    if plan.pocket > 0:
        cuts.append((s, plan.s_end - plan.pocket, through, True))
        s = plan.s_end - plan.pocket
        if plan.solid > 0:
            cuts.append((s, plan.s_end - plan.solid, full, True))
            s = plan.s_end - plan.solid
        cuts.append((s, plan.s_end, full, plan.solid <= 0))
    elif plan.solid > 0:
        cuts.append((s, plan.s_end - plan.solid, through, True))
        cuts.append((plan.s_end - plan.solid, plan.s_end, through, False))
    else:
        cuts.append((s, plan.s_end, through, True))
    return cuts


def build_direction(road: Road, d: int, plan: DirPlan, sink: TownSink) -> DirLanes:
    """Lanes of one road direction, linked segment to segment; returns first/last rows."""
    out = DirLanes()
    prev: dict[tuple[str, int], int] = {}
    roles: list[str] = []
    row: list[int] = []
    for k, (s0, s1, roles, legal) in enumerate(_segments(plan)):
        s = plan.path.sample_s(s0, s1, plan.dense())
        base, tangent = plan.path.frame(s)
        normal = right_normal(tangent)
        row, keyed, t_count = [], {}, 0
        for role in roles:
            i = t_count if role == "T" else 0
            t_count += role == "T"
            pts = base + plan.offset(role, i, s)[:, None] * normal
            sid = f"r{road.index}/{'fb'[d]}/{k}/{role}{i if role == 'T' else ''}"
            keyed[(role, i)] = sink.add_lane(pts, plan.width, road.speed_limit, sid)
            row.append(keyed[(role, i)])
        sink.neighbours(row, legal)
        for key, b in keyed.items():
            if key in prev:
                sink.link(prev[key], b)
        # pockets branch off the outer through lanes where they appear (a lane split)
        if ("L", 0) in keyed and ("L", 0) not in prev and prev:
            sink.link(prev[("T", 0)], keyed[("L", 0)])
        if ("R", 0) in keyed and ("R", 0) not in prev and prev:
            sink.link(prev[("T", plan.lanes - 1)], keyed[("R", 0)])
        if not prev:
            out.first = row
        prev = keyed
    out.last, out.last_roles = row, list(roles)
    return out


def build_edges(
    road: Road, plans: tuple[DirPlan, DirPlan], arms: tuple[Arm, Arm], p: TownParams, sink: TownSink
) -> dict:
    """Both road edges of `road` between the junction curbs; returns the arms' edge ends.

    Returns:
        {(node, road): ((ccw end point, outward tangent), (cw end point, outward tangent))}
    """
    path, length = road.path, road.path.length
    arm_u, arm_v = arms
    s0, s1 = arm_u.r_core, length - arm_v.r_core
    extra = plans[0].dense() + tuple(length - x for x in plans[1].dense())
    s = path.sample_s(s0, s1, extra)
    base, tangent = path.frame(s)
    normal = right_normal(tangent)
    right = base + plans[0].half_width(s, p.shoulder)[:, None] * normal
    left = base - plans[1].half_width(length - s, p.shoulder)[:, None] * normal
    sink.elements.road_edges.append(PolylineElement(right, source_id=f"r{road.index}/edge_right"))
    sink.elements.road_edges.append(PolylineElement(left, source_id=f"r{road.index}/edge_left"))
    t = tangent[[0, -1]]
    # arm at u looks along +t: its ccw (left) side is the left edge; at v it looks along -t
    return {
        (arm_u.node, road.index): ((left[0], t[0]), (right[0], t[0])),
        (arm_v.node, road.index): ((right[-1], -t[1]), (left[-1], -t[1])),
    }


def crosswalk(arm: Arm, plans: tuple[DirPlan, DirPlan], p: TownParams, road: Road) -> CrosswalkElement:
    """Crosswalk polygon across the whole road just outside the junction on `arm`."""
    length = road.path.length
    a = arm.r_core + 1.0
    b = a + p.crosswalk_width
    # the crosswalk in road (u -> v) arc length; at v it is measured from the far end
    s = np.array([a, b]) if arm.out_dir == 0 else length - np.array([a, b])
    wr = plans[0].half_width(s, p.shoulder) - p.shoulder
    wl = plans[1].half_width(length - s, p.shoulder) - p.shoulder
    r = road.path.offset(s, wr)
    left = road.path.offset(s, -wl)
    poly = np.stack([left[0], r[0], r[1], left[1]])
    return CrosswalkElement(poly, source_id=f"n{arm.node}/r{road.index}/crosswalk")


def stop_line(plan_in: DirPlan) -> np.ndarray:
    """(2, 2) [m] line across the incoming lanes at their end, from the centre line out."""
    s = np.array([plan_in.s_end, plan_in.s_end])
    n = plan_in.lanes + plan_in.left + plan_in.right
    return plan_in.path.offset(s, np.array([0.0, n * plan_in.width]))


def build_roads(
    net: Network, arm_of: dict[tuple[int, int], Arm], p: TownParams, sink: TownSink
) -> tuple[dict[tuple[int, int], DirLanes], dict[tuple[int, int], DirPlan], dict]:
    """Lanes, edges and crosswalks of every road.

    Returns:
        (lanes per (road, direction), plan per (road, direction), edge ends per (node, road)).
    """
    dirs: dict[tuple[int, int], DirLanes] = {}
    plans: dict[tuple[int, int], DirPlan] = {}
    ends: dict = {}
    for road in net.roads:
        arm_u, arm_v = arm_of[(road.u, road.index)], arm_of[(road.v, road.index)]
        pr = (plan_direction(road, 0, arm_u, arm_v, p), plan_direction(road, 1, arm_v, arm_u, p))
        for d in (0, 1):
            plans[(road.index, d)] = pr[d]
            dirs[(road.index, d)] = build_direction(road, d, pr[d], sink)
        ends.update(build_edges(road, pr, (arm_u, arm_v), p, sink))
        for arm in (arm_u, arm_v):
            if arm.crosswalk:
                sink.elements.crosswalks.append(crosswalk(arm, pr, p, road))
    return dirs, plans, ends
