"""Roundabouts: a one-way single-lane ring, counter-clockwise (right-hand traffic).

Every arm has an entry connector joining the ring tangentially at `angle + alpha` and an exit
connector leaving it at `angle - alpha`; the ring is cut into pieces at these points so the
lane graph says where a vehicle may leave. All ring, entry and exit lanes are junction lanes
(in_junction=True). Curbs: a circular central island and, between neighbouring arms, an outer
curb that blends from the arm's road edge into a circle around the ring.
"""

from __future__ import annotations

import math

import numpy as np

from selfplaydrive.maps.elements import PolylineElement
from selfplaydrive.maps.procedural.geometry import CURVE_STEP, arc, smooth_link
from selfplaydrive.maps.procedural.layout import DirLanes, Junction, TownSink
from selfplaydrive.maps.procedural.params import TownParams

FLARE = 4.0  # [m] the arm's road edge ends this far outside the outer curb circle
ALPHA = math.radians(32.0)  # angle between an arm's axis and its entry / exit point on the ring
FILLET = math.radians(14.0)  # angular length of the curb blend from an arm into the circle
MIN_GAP = math.radians(60.0)  # arms closer than this cannot share a roundabout


def radii(p: TownParams) -> tuple[float, float, float]:
    """(ring centerline, outer curb, island curb) radii [m]."""
    r = p.roundabout_radius
    half = p.roundabout_lane_width / 2 + p.shoulder
    return r, r + half, r - half


def fits(j: Junction) -> bool:
    """Whether a roundabout can replace junction j (3+ arms, 1 lane each way, arms spread out)."""
    if len(j.arms) < 3 or any(a.lanes != 1 for a in j.arms):
        return False
    return min(j.gap_after(k) for k in range(len(j.arms))) >= MIN_GAP


def set_setbacks(j: Junction, p: TownParams) -> None:
    """r_core / r_lane of the arms: road edges end `FLARE` outside the outer curb circle."""
    _, r_out, _ = radii(p)
    for arm in j.arms:
        hw = max(arm.hw_ccw, arm.hw_cw)
        arm.r_core = arm.r_core_min = math.sqrt((r_out + FLARE) ** 2 - hw**2)
        arm.r_lane = arm.r_core + 1.0 + ((p.crosswalk_width + 1.0) if arm.crosswalk else 0.0)


def _arm_angles(j: Junction) -> list[float]:
    """Heading of each arm's reference point at r_core, seen from the centre [rad]."""
    out = []
    for arm in j.arms:
        q = arm.path.frame(np.array([arm.r_core]))[0][0] - j.center
        out.append(math.atan2(q[1], q[0]))
    return out


def _ring_point(j: Junction, r: float, theta: float) -> tuple[np.ndarray, np.ndarray]:
    c, s = math.cos(theta), math.sin(theta)
    return j.center + r * np.array([c, s]), np.array([-s, c])


def build_roundabout(
    j: Junction, dirs: dict[tuple[int, int], DirLanes], ends: dict, sink: TownSink, p: TownParams
) -> None:
    """Ring pieces, entry and exit connectors and curbs of roundabout j."""
    r, r_out, r_in = radii(p)
    speed, width = p.roundabout_speed_limit, p.roundabout_lane_width
    phi = _arm_angles(j)
    m = len(j.arms)
    gaps = [(phi[(k + 1) % m] - phi[k]) % (2 * math.pi) for k in range(m)]
    alpha = [min(ALPHA, 0.3 * gaps[k], 0.3 * gaps[k - 1]) for k in range(m)]
    # events counter-clockwise: exit of arm k, entry of arm k, exit of arm k + 1 ...
    events = []
    for k in range(m):
        events += [("exit", k, phi[k] - alpha[k]), ("entry", k, phi[k] + alpha[k])]
    pieces = []
    for i, (_, _, a0) in enumerate(events):
        a1 = events[(i + 1) % len(events)][2]
        while a1 <= a0:
            a1 += 2 * math.pi
        pts = arc(j.center, r, a0, a1, CURVE_STEP)
        pieces.append(sink.add_lane(pts, width, speed, f"rb{j.node}/ring{i}", in_junction=True))
    for i in range(len(pieces)):
        sink.link(pieces[i], pieces[(i + 1) % len(pieces)])
    lanes = sink.elements.lanes
    for i, (kind, k, theta) in enumerate(events):
        arm = j.arms[k]
        lead = arm.r_lane - arm.r_core
        pt, tan = _ring_point(j, r, theta)
        if kind == "entry":
            for src in dirs[(arm.road, arm.in_dir)].last:
                a = lanes[src].centerline
                d0 = (a[-1] - a[-2]) / np.hypot(*(a[-1] - a[-2]))
                pts = np.concatenate([a[-1:], smooth_link(a[-1] + lead * d0, d0, pt, tan, CURVE_STEP)])
                e = sink.add_lane(pts, lanes[src].width, speed, f"rb{j.node}/entry{k}", in_junction=True)
                sink.link(src, e)
                sink.link(e, pieces[i])
        else:
            for dst in dirs[(arm.road, arm.out_dir)].first:
                b = lanes[dst].centerline
                d3 = (b[1] - b[0]) / np.hypot(*(b[1] - b[0]))
                pts = np.concatenate([smooth_link(pt, tan, b[0] - lead * d3, d3, CURVE_STEP), b[:1]])
                x = sink.add_lane(pts, lanes[dst].width, speed, f"rb{j.node}/exit{k}", in_junction=True)
                sink.link(pieces[i - 1], x)
                sink.link(x, dst)
    island = arc(j.center, r_in, 0.0, 2 * math.pi, CURVE_STEP)
    island[-1] = island[0]
    sink.elements.road_edges.append(PolylineElement(island, source_id=f"rb{j.node}/island"))
    for k in range(m):
        curb = outer_curb(j, k, ends, r_out)
        sink.elements.road_edges.append(PolylineElement(curb, source_id=f"rb{j.node}/curb{k}"))


def outer_curb(j: Junction, k: int, ends: dict, r_out: float) -> np.ndarray:
    """Curb from arm k's ccw road edge around the ring to the next arm's cw road edge.

    A smooth_link turns from the arm's edge onto the circle of radius `r_out` `FILLET` past
    the edge, the circle follows, and a second smooth_link turns out onto the next arm.
    """
    a, b = j.arms[k], j.arms[(k + 1) % len(j.arms)]
    pa, ta = ends[(a.node, a.road)][0]
    pb, tb = ends[(b.node, b.road)][1]
    va, vb = pa - j.center, pb - j.center
    a0 = math.atan2(va[1], va[0]) + FILLET
    a1 = math.atan2(vb[1], vb[0]) - FILLET
    while a1 <= a0:
        a1 += 2 * math.pi
    qa, da = _ring_point(j, r_out, a0)
    qb, db = _ring_point(j, r_out, a1)
    pts = np.concatenate(
        [
            smooth_link(pa, -ta, qa, da, CURVE_STEP)[:-1],
            arc(j.center, r_out, a0, a1, CURVE_STEP),
            smooth_link(qb, db, pb, tb, CURVE_STEP)[1:],
        ]
    )
    pts[0], pts[-1] = pa, pb  # exact shared end points: the edges close into loops
    return pts
