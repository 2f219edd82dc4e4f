"""`generate_town`: seed + `TownParams` -> `MapElements` of a plausible town (section 2.1).

Pipeline: street graph (network.py) -> junction arms and turn classes (intersections.py) ->
roundabouts, lights, priority roads, pockets, crosswalks (regulation.py) -> junction setbacks
-> road lanes and edges (lanes.py) -> junction connectors and curbs (intersections.py,
roundabouts.py) -> stop lines and traffic lights (regulation.py).

Deterministic: the only randomness is one `numpy.random.default_rng(seed)`, drawn in a fixed
order, and no step depends on hashing or set iteration order.
"""

from __future__ import annotations

from dataclasses import fields

import numpy as np

from selfplaydrive.errors import ConfigError
from selfplaydrive.maps.elements import MapElements
from selfplaydrive.maps.procedural import intersections, roundabouts
from selfplaydrive.maps.procedural.lanes import build_roads
from selfplaydrive.maps.procedural.layout import Junction, TownSink
from selfplaydrive.maps.procedural.network import build_network
from selfplaydrive.maps.procedural.params import TownParams
from selfplaydrive.maps.procedural.regulation import assign_kinds, build_regulation, decide_features


def check_seed(seed: object, who: str) -> int:
    """The seed as an int.

    Raises:
        ConfigError: Unless `seed` is a non-negative integer (bools are refused).
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ConfigError(f"{who}: seed must be a non-negative integer, got {seed!r}")
    return int(seed)


def describe(seed: int, params: TownParams) -> str:
    """The generator call that rebuilds a town: seed plus the parameters that differ from defaults."""
    default = TownParams()
    changed = [
        f"{f.name}={getattr(params, f.name)!r}"
        for f in fields(params)
        if getattr(params, f.name) != getattr(default, f.name)
    ]
    return "selfplaydrive.maps.procedural.generate_town(" + ", ".join([f"seed={seed}", *changed]) + ")"


def generate_town(seed: int, params: TownParams | None = None) -> MapElements:
    """Generate a town from a seed.

    Args:
        seed: Non-negative integer; the same seed and params give bit-identical output.
        params: Town parameters (default `TownParams()`: a 1.6 x 1.6 km town).

    Returns:
        `MapElements` (lanes, road edges, stop and yield lines, traffic lights, crosswalks) in a local
        metric frame with the town's south-west grid node near (0, 0).

    Raises:
        ConfigError: If `seed` is not a non-negative integer or a parameter is out of range.
    """
    return build_town(seed, params)[0]


def junction_counts(junctions: list[Junction]) -> dict[str, int]:
    """Number of junctions of each kind ("signal", "priority", "uncontrolled", "roundabout",
    "bend") plus "intersections": all 3+ arm junctions that are not roundabouts."""
    counts = {k: 0 for k in ("signal", "priority", "uncontrolled", "roundabout", "bend")}
    for j in junctions:
        counts[j.kind] += 1
    counts["intersections"] = counts["signal"] + counts["priority"] + counts["uncontrolled"]
    return counts


def build_town(seed: int, params: TownParams | None = None) -> tuple[MapElements, list[Junction]]:
    """`generate_town` that also returns the junctions (kinds, arms, setbacks) for inspection."""
    seed = check_seed(seed, "generate_town")
    p = (params if params is not None else TownParams()).validate()
    rng = np.random.default_rng(seed)
    net = build_network(rng, p)
    junctions = intersections.make_junctions(net)
    assign_kinds(rng, junctions, net, p)
    decide_features(rng, junctions, net, p)
    for j in junctions:
        (roundabouts.set_setbacks if j.kind == "roundabout" else intersections.set_setbacks)(j, p)
    arm_of = {(a.node, a.road): a for j in junctions for a in j.arms}
    for road in net.roads:
        intersections.fit_street(road, arm_of[(road.u, road.index)], arm_of[(road.v, road.index)])
    sink = TownSink(name=f"town_{seed}", source=describe(seed, p))
    dirs, plans, ends = build_roads(net, arm_of, p, sink)
    for j in junctions:
        if j.kind == "roundabout":
            roundabouts.build_roundabout(j, dirs, ends, sink, p)
        else:
            intersections.build_connectors(j, dirs, sink)
            intersections.build_corners(j, ends, sink)
    build_regulation(junctions, dirs, plans, sink)
    return sink.elements, junctions
