"""Junctions of a procedural town: arms, turn classification, setbacks, connector lanes, curbs.

Right-hand traffic. At a junction each approach lane gets connector lanes (in_junction=True)
only for the moves it may legally make (paper section 2.1: the lane graph holds legal moves
only): left turns from the left pocket or the leftmost lane, right turns from the right pocket
or the rightmost lane, straight on from the through lanes. Connectors run straight across the
crosswalk zone and follow a circular-like cubic Bezier inside the junction.
"""

from __future__ import annotations

import math

import numpy as np

from selfplaydrive.errors import ConfigError
from selfplaydrive.maps.elements import PolylineElement
from selfplaydrive.maps.procedural.geometry import CURVE_STEP, smooth_link, unit
from selfplaydrive.maps.procedural.layout import LEFT, RIGHT, STRAIGHT, Arm, DirLanes, Junction, TownSink
from selfplaydrive.maps.procedural.network import Network, Road
from selfplaydrive.maps.procedural.params import TownParams

ARM_PROBE = 10.0  # [m] the arm heading is measured to the reference point this far out
MIN_CORNER_RADIUS = 1.0  # [m] tightest curb rounding when a short street needs room
MIN_BODY = 8.0  # [m] lane length a street keeps between its two junctions
NEAR_STRAIGHT = math.radians(170.0)  # wider gaps: edge lines meet far away or never, no setback
TURN_SPLIT = math.pi / 4  # heading change [rad] separating straight on from a turn


def make_junctions(net: Network) -> list[Junction]:
    """One `Junction` per node, arms sorted counter-clockwise, moves classified."""
    junctions = []
    for node, roads in enumerate(net.node_roads):
        center = net.nodes[node]
        arms = []
        for r in roads:
            road = net.roads[r]
            out_dir = 0 if road.u == node else 1
            path = road.path if out_dir == 0 else road.path.reversed()
            probe = path.frame(np.array([min(ARM_PROBE, path.length / 4)]))[0][0] - center
            arms.append(
                Arm(
                    node,
                    r,
                    out_dir,
                    math.atan2(probe[1], probe[0]),
                    path,
                    road.lanes,
                    road.lane_width,
                    road.main,
                )
            )
        arms.sort(key=lambda a: a.angle)
        j = Junction(node=node, center=center, arms=arms, kind="bend" if len(arms) == 2 else "uncontrolled")
        for k in range(len(arms)):
            arms[k].moves = classify_moves(j, k)
        junctions.append(j)
    return junctions


def turn_angle(j: Junction, a: int, b: int) -> float:
    """Heading change [rad] (left positive) driving in on arm a and out on arm b."""
    d = j.arms[b].angle - (j.arms[a].angle + math.pi)
    return math.atan2(math.sin(d), math.cos(d))


def classify_moves(j: Junction, a: int) -> dict[str, int]:
    """Turn kind -> target arm for the approach on arm a (no U-turns)."""
    others = sorted((turn_angle(j, a, b), b) for b in range(len(j.arms)) if b != a)
    if len(others) == 1:
        return {STRAIGHT: others[0][1]}
    if len(others) == 3:
        return {RIGHT: others[0][1], STRAIGHT: others[1][1], LEFT: others[2][1]}
    (t1, b1), (t2, b2) = others
    if t1 < -TURN_SPLIT and t2 > TURN_SPLIT:
        return {RIGHT: b1, LEFT: b2}
    if t2 <= TURN_SPLIT:
        return {RIGHT: b1, STRAIGHT: b2}
    return {STRAIGHT: b1, LEFT: b2}


def set_setbacks(j: Junction, p: TownParams) -> None:
    """Distances r_core (curbs start) and r_lane (stop line) of every arm of a non-roundabout.

    The corner of two neighbouring arms lies where their edge lines meet; t below is the
    distance along the arm to that point, then `corner_radius` of curb rounding follows.
    """
    m = len(j.arms)
    for k, arm in enumerate(j.arms):
        t = 0.0
        nxt, prv = j.arms[(k + 1) % m], j.arms[k - 1]
        g_next, g_prev = j.gap_after(k), j.gap_after((k - 1) % m)
        if g_next < NEAR_STRAIGHT:
            t = max(t, (nxt.hw_cw + arm.hw_ccw * math.cos(g_next)) / math.sin(g_next))
        if g_prev < NEAR_STRAIGHT:
            t = max(t, (prv.hw_ccw + arm.hw_cw * math.cos(g_prev)) / math.sin(g_prev))
        arm.r_core = t + p.corner_radius if t > 0 else 2.0
        arm.r_core_min = t + MIN_CORNER_RADIUS if t > 0 else 2.0
        arm.r_lane = arm.r_core + 1.0 + ((p.crosswalk_width + 1.0) if arm.crosswalk else 0.0)


def fit_street(road: Road, arm_u: Arm, arm_v: Arm) -> None:
    """Make the two junctions of a short, wide street leave `MIN_BODY` of lane between them.

    First the crosswalks at its ends go, then the corner curbs get tighter (down to
    `MIN_CORNER_RADIUS`); if that is not enough the parameters cannot make a town.

    Raises:
        ConfigError: Naming the street, the room left and what to change.
    """

    def body() -> float:
        return road.path.length - arm_u.r_lane - arm_v.r_lane

    for arm in (arm_u, arm_v):
        if body() < MIN_BODY and arm.crosswalk:
            arm.crosswalk = False
            arm.r_lane = arm.r_core + 1.0
    for arm in (arm_u, arm_v):
        if body() < MIN_BODY:
            arm.r_core = max(arm.r_core_min, arm.r_core - (MIN_BODY - body()))
            arm.r_lane = arm.r_core + 1.0
    if body() < MIN_BODY:
        raise ConfigError(
            f"street r{road.index} ({road.path.length:.1f} m between its nodes) leaves only "
            f"{body():.1f} m of lane between its junctions, at least {MIN_BODY} m are needed: increase "
            "TownParams.block_size or use fewer/narrower lanes (lanes_per_direction, lane_width, "
            "shoulder, corner_radius)"
        )


def approach_lanes(arm: Arm, roles: list[str]) -> dict[str, list[int]]:
    """Positions (0 = leftmost) of the approach lanes that serve each move of `arm`."""
    through = [i for i, r in enumerate(roles) if r == "T"]
    n = len(through)
    out: dict[str, list[int]] = {}
    if STRAIGHT not in arm.moves:  # stem of a T: split the lanes between the two turns
        if n == 1:
            return {mv: through for mv in arm.moves}
        half = (n + 1) // 2
        split = {LEFT: through[:half], RIGHT: through[half:]}
        return {mv: split[mv] for mv in arm.moves}
    straight = list(through)
    if LEFT in arm.moves:
        out[LEFT] = [roles.index("L")] if "L" in roles else through[:1]
        if "L" not in roles and n >= 3:
            straight.remove(through[0])
    if RIGHT in arm.moves:
        out[RIGHT] = [roles.index("R")] if "R" in roles else through[-1:]
        if "R" not in roles and n >= 3:
            straight.remove(through[-1])
    out[STRAIGHT] = straight
    return out


def map_lanes(move: str, src: list[int], dst: list[int]) -> list[tuple[int, int]]:
    """Pairs (source, target) of lanes for one move; turns keep to the inside lanes."""
    j, k = len(src), len(dst)
    if move == LEFT:
        return [(s, dst[min(i, k - 1)]) for i, s in enumerate(src)]
    if move == RIGHT:
        return [(s, dst[max(k - j + i, 0)]) for i, s in enumerate(src)]
    if j == 1:
        return [(src[0], dst[k // 2])]
    return [(s, dst[round(i * (k - 1) / (j - 1))]) for i, s in enumerate(src)]


def _end_dir(line: np.ndarray, at_end: bool) -> np.ndarray:
    return unit(line[-1] - line[-2]) if at_end else unit(line[1] - line[0])


def connector(
    sink: TownSink,
    src: int,
    dst: int,
    lead_in: float,
    lead_out: float,
    step: float,
    source_id: str,
    speed: float,
) -> int:
    """Add a junction lane from the end of lane `src` to the start of lane `dst`.

    The connector runs `lead_in` [m] straight on, bends along `smooth_link`, and runs the
    last `lead_out` [m] straight into `dst`.
    """
    lanes = sink.elements.lanes
    a, b = lanes[src].centerline, lanes[dst].centerline
    p0, d0 = a[-1], _end_dir(a, True)
    p3, d3 = b[0], _end_dir(b, False)
    q0, q3 = p0 + lead_in * d0, p3 - lead_out * d3
    mid = smooth_link(q0, d0, q3, d3, step)
    pts = np.concatenate([p0[None], mid, p3[None]])
    keep = np.concatenate([[True], np.hypot(*np.diff(pts, axis=0).T) > 1e-3])
    pts = pts[keep]
    pts[-1] = p3
    idx = sink.add_lane(pts, lanes[src].width, speed, source_id, in_junction=True)
    sink.link(src, idx)
    sink.link(idx, dst)
    return idx


def build_connectors(j: Junction, dirs: dict[tuple[int, int], DirLanes], sink: TownSink) -> None:
    """Connector lanes for every legal move of a (non-roundabout) junction."""
    lanes = sink.elements.lanes
    for ai, arm in enumerate(j.arms):
        din = dirs[(arm.road, arm.in_dir)]
        serve = approach_lanes(arm, din.last_roles)
        for move, bi in sorted(arm.moves.items()):
            target = j.arms[bi]
            dst = dirs[(target.road, target.out_dir)].first
            src = [din.last[i] for i in serve[move]]
            for k, (s, d) in enumerate(map_lanes(move, src, dst)):
                speed = min(lanes[s].speed_limit, lanes[d].speed_limit)
                sid = f"n{j.node}/a{ai}{move[0]}{k}"  # node, arm, move (l/s/r), pair
                connector(
                    sink, s, d, arm.r_lane - arm.r_core, target.r_lane - target.r_core, CURVE_STEP, sid, speed
                )


def corner_curb(j: Junction, k: int, ends: dict[tuple[int, int], tuple], step: float) -> np.ndarray:
    """Curb from arm k's ccw road edge to the next arm's cw road edge (shared end points)."""
    a, b = j.arms[k], j.arms[(k + 1) % len(j.arms)]
    pa, ta = ends[(a.node, a.road)][0]  # ccw edge end, outward tangent
    pb, tb = ends[(b.node, b.road)][1]  # cw edge end
    # built like the connector lanes (smooth_link): the lanes next to the curb, whose tangent
    # lines are the curb's moved inwards, follow it at about a constant distance; the
    # straight side of a T becomes a straight line or a gentle S between unequal widths
    pts = smooth_link(pa, -ta, pb, tb, step)
    pts[0], pts[-1] = pa, pb  # exact shared end points: curbs and road edges close into loops
    return pts


def build_corners(j: Junction, ends: dict[tuple[int, int], tuple], sink: TownSink) -> None:
    """Road edges between neighbouring arms of a junction."""
    for k in range(len(j.arms)):
        pts = corner_curb(j, k, ends, CURVE_STEP)
        sink.elements.road_edges.append(PolylineElement(pts, source_id=f"n{j.node}/corner{k}"))
