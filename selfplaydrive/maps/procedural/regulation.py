"""Junction control and road features: roundabouts, lights, priority roads, pockets, crosswalks.

Paper section 2.1: traffic lights, yield signs and stop signs are all lines where a vehicle may
have to stop; the generator writes

- traffic-light stop lines on every approach of a signalised junction, with the two crossing
  axes in different signal groups (approaches of one axis share a group);
- stop-sign lines (`StopKind.STOP`) on the two minor approaches of a minor street crossing a
  main road (4-way priority junctions whose priority road is a main road; no randomness: the
  rule follows from the junction kinds, so the rest of the town is unchanged);
- yield lines (`StopKind.YIELD`) on the minor approaches of every other priority junction and
  on every roundabout entry;
- nothing at right-hand-rule junctions (minor x minor, unsigned) and at bends.
"""

from __future__ import annotations

import warnings

import numpy as np

from selfplaydrive.maps.elements import StopKind, StopLineElement, TrafficLightElement
from selfplaydrive.maps.procedural import roundabouts
from selfplaydrive.maps.procedural.lanes import DirPlan, stop_line
from selfplaydrive.maps.procedural.layout import LEFT, RIGHT, STRAIGHT, DirLanes, Junction, TownSink
from selfplaydrive.maps.procedural.network import Network
from selfplaydrive.maps.procedural.params import TownParams

MIN_ROAD_FOR_POCKETS = 80.0  # [m] street chord below which no pockets are planned


def _straight_pairs(j: Junction) -> list[tuple[int, int]]:
    """Arm pairs (a, b), a < b, where each is the other's straight-on target."""
    pairs = []
    for a, arm in enumerate(j.arms):
        b = arm.moves.get(STRAIGHT, -1)
        if b > a and j.arms[b].moves.get(STRAIGHT, -1) == a:
            pairs.append((a, b))
    return pairs


def _place_roundabouts(rng: np.random.Generator, junctions: list[Junction], net: Network, count: int) -> None:
    order = rng.permutation(len(junctions))
    # prefer 4-way nodes: a roundabout there replaces the busiest kind of crossing
    order = sorted(order.tolist(), key=lambda i: -len(junctions[i].arms))
    blocked: set[int] = set()
    placed = 0
    for i in order:
        if placed >= count:
            break
        j = junctions[i]
        if i in blocked or not roundabouts.fits(j):
            continue
        j.kind = "roundabout"
        placed += 1
        for arm in j.arms:  # never two roundabouts at the ends of one street
            road = net.roads[arm.road]
            blocked.update((road.u, road.v))
    if placed < count:
        warnings.warn(
            f"procedural town: placed {placed} of num_roundabouts={count} roundabouts; only nodes with "
            "3+ arms of one lane per direction, 60 degrees apart and not next to another roundabout "
            "qualify (use minor_lanes_per_direction=1 or a larger size)",
            stacklevel=5,  # the caller of generate_town
        )


def assign_kinds(rng: np.random.Generator, junctions: list[Junction], net: Network, p: TownParams) -> None:
    """Choose roundabouts, signalised, priority and right-hand-rule junctions."""
    _place_roundabouts(rng, junctions, net, p.num_roundabouts)
    plain = [j for j in junctions if j.kind == "uncontrolled"]
    # main x main crossings first, ties broken at random
    score = [sum(a.main for a in j.arms) + float(rng.uniform()) for j in plain]
    num_signal = round(p.signalised_share * len(plain))
    ranked = sorted(range(len(plain)), key=lambda i: -score[i])
    for rank, i in enumerate(ranked):
        j = plain[i]
        pairs = _straight_pairs(j)
        if rank < num_signal:
            j.kind = "signal"
            axis = set(pairs[0]) if pairs else {0}
            j.phases = [0 if k in axis else 1 for k in range(len(j.arms))]
            continue
        mains = [k for k, a in enumerate(j.arms) if a.main]
        main_pairs = [pr for pr in pairs if all(k in mains for k in pr)]
        if main_pairs:
            j.kind, j.priority = "priority", set(main_pairs[int(rng.integers(len(main_pairs)))])
        elif pairs and rng.uniform() < p.priority_share:
            j.kind, j.priority = "priority", set(pairs[int(rng.integers(len(pairs)))])


def decide_features(rng: np.random.Generator, junctions: list[Junction], net: Network, p: TownParams) -> None:
    """Turn pockets and crosswalks per arm, then the half widths the setbacks need."""
    for j in junctions:
        for arm in j.arms:
            u_left, u_right, u_walk = rng.uniform(size=3)
            road = net.roads[arm.road]
            chord = float(np.hypot(*(net.nodes[road.u] - net.nodes[road.v])))
            room = chord >= MIN_ROAD_FOR_POCKETS
            junction = j.kind in ("signal", "priority", "uncontrolled")
            can = junction and arm.main and room and STRAIGHT in arm.moves
            arm.left_pocket = bool(can and LEFT in arm.moves and u_left < p.left_turn_lane_share)
            arm.right_pocket = bool(can and RIGHT in arm.moves and u_right < p.right_turn_lane_share)
            arm.crosswalk = bool(j.kind != "bend" and u_walk < p.crosswalk_density)
            arm.hw_ccw = arm.num_in_lanes * arm.lane_width + p.shoulder
            arm.hw_cw = arm.lanes * arm.lane_width + p.shoulder


def stop_kind(j: Junction) -> StopKind:
    """The sign on the minor approaches of a priority junction or the entries of a roundabout.

    STOP where a minor street crosses a main road (four arms, the priority road a main road):
    crossing two or more lanes per direction of faster traffic (paper section 2.1 treats stop
    and yield signs alike; the STOP kind is what the `stop_sign` reward term and the stop-sign
    suite act on). YIELD everywhere else.
    """
    crossing_main = len(j.arms) == 4 and bool(j.priority) and all(j.arms[k].main for k in j.priority)
    return StopKind.STOP if j.kind == "priority" and crossing_main else StopKind.YIELD


def build_regulation(
    junctions: list[Junction],
    dirs: dict[tuple[int, int], DirLanes],
    plans: dict[tuple[int, int], DirPlan],
    sink: TownSink,
) -> None:
    """Traffic-light stop lines, stop-sign and yield lines of every junction."""
    group = 0
    for j in junctions:
        for k, arm in enumerate(j.arms):
            key = (arm.road, arm.in_dir)
            line = stop_line(plans[key])
            lanes = list(dirs[key].last)
            sid = f"n{j.node}/r{arm.road}"
            if j.kind == "signal":
                light = TrafficLightElement(line, group + j.phases[k], lanes, source_id=f"{sid}/light")
                sink.elements.traffic_lights.append(light)
            elif j.kind == "roundabout" or (j.kind == "priority" and k not in j.priority):
                kind = stop_kind(j)
                stop = StopLineElement(line, kind, lanes, source_id=f"{sid}/{kind.name.lower()}")
                sink.elements.stop_lines.append(stop)
        if j.kind == "signal":
            group += max(j.phases) + 1
