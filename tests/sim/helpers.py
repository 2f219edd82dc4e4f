"""Hand-built scenarios for the simulator tests (no spawner needed)."""

from __future__ import annotations

import copy
from collections.abc import Sequence

import numpy as np

from selfplaydrive.scenario.types import COEFF_NAMES, HIDDEN_PARAMS, Scenario

# coefficients that make every term visible and never terminate (C < 0.5)
DEFAULT_COEFFS = dict(
    waypoint_radius=2.0,
    collision=0.3,
    offroad=0.3,
    red_light=0.5,
    comfort=0.005,
    center=1e-3,
    center_bias=0.1,
    align=1e-2,
)


def make_scenario(
    agents: Sequence[dict],
    A: int = 4,
    S: int = 2,
    P: int = 2,
    K: int = 3,
    T: int = 3,
    statics: Sequence[dict] = (),
    peds: Sequence[dict] = (),
    lights: Sequence[tuple[int, float]] = (),
    episode_length: float = 20.0,
    map_index: int = 0,
) -> Scenario:
    """Scenario with agents given as dicts: xy, heading, speed, length, width, waypoints,
    coeffs (dict overriding DEFAULT_COEFFS), hidden (friction, accel gain, steer gain)."""
    f4 = np.float32
    sc = Scenario(
        map_index=map_index,
        region=np.array([-100, -100, 300, 100], f4),
        agent_valid=np.zeros(A, bool),
        agent_xy=np.zeros((A, 2), f4),
        agent_heading=np.zeros(A, f4),
        agent_speed=np.zeros(A, f4),
        agent_length=np.full(A, 4.5, f4),
        agent_width=np.full(A, 2.0, f4),
        agent_parked=np.zeros(A, bool),
        agent_lane=np.full(A, -1, np.int32),
        waypoints=np.zeros((A, K, 2), f4),
        num_waypoints=np.zeros(A, np.int32),
        coeffs=np.tile(np.array([DEFAULT_COEFFS[n] for n in COEFF_NAMES], f4), (A, 1)),
        hidden=np.tile(np.array([1.0, 1.0, 1.0], f4), (A, 1)),
        static_valid=np.zeros(S, bool),
        static_xy=np.zeros((S, 2), f4),
        static_heading=np.zeros(S, f4),
        static_length=np.full(S, 4.5, f4),
        static_width=np.full(S, 2.0, f4),
        ped_valid=np.zeros(P, bool),
        ped_path=np.zeros((P, T, 2), f4),
        ped_num_points=np.zeros(P, np.int32),
        ped_speed=np.zeros(P, f4),
        ped_start_time=np.zeros(P, f4),
        ped_size=np.full((P, 2), 0.5, f4),
        lights_enabled=bool(lights),
        light_state=np.array([s for s, _ in lights], np.int8),
        light_time_left=np.array([t for _, t in lights], f4),
        episode_length=episode_length,
    )
    assert len(HIDDEN_PARAMS) == 3
    for i, a in enumerate(agents):
        sc.agent_valid[i] = True
        sc.agent_xy[i] = a.get("xy", (0.0, 0.0))
        sc.agent_heading[i] = a.get("heading", 0.0)
        sc.agent_speed[i] = a.get("speed", 0.0)
        sc.agent_length[i] = a.get("length", 4.5)
        sc.agent_width[i] = a.get("width", 2.0)
        wps = np.asarray(a.get("waypoints", []), f4).reshape(-1, 2)
        sc.num_waypoints[i] = len(wps)
        if len(wps):
            sc.waypoints[i, : len(wps)] = wps
            sc.waypoints[i, len(wps) :] = wps[-1]
        c = dict(DEFAULT_COEFFS, **a.get("coeffs", {}))
        sc.coeffs[i] = [c[n] for n in COEFF_NAMES]
        sc.hidden[i] = a.get("hidden", (1.0, 1.0, 1.0))
    for k, s in enumerate(statics):
        sc.static_valid[k] = True
        sc.static_xy[k] = s["xy"]
        sc.static_heading[k] = s.get("heading", 0.0)
        sc.static_length[k] = s.get("length", 4.5)
        sc.static_width[k] = s.get("width", 2.0)
    for k, p in enumerate(peds):
        path = np.asarray(p["path"], f4)
        sc.ped_valid[k] = True
        sc.ped_path[k, : len(path)] = path
        sc.ped_path[k, len(path) :] = path[-1]
        sc.ped_num_points[k] = len(path)
        sc.ped_speed[k] = p.get("speed", 1.0)
        sc.ped_start_time[k] = p.get("start", 0.0)
        sc.ped_size[k] = p.get("size", (0.5, 0.5))
    return sc


class FixedSpawner:
    """Spawner returning copies of given scenarios in turn (one per sample call)."""

    def __init__(self, *scenarios: Scenario) -> None:
        self.scenarios = scenarios
        self.calls = 0

    def sample(self, road_map, rng, map_index: int = 0) -> Scenario:
        sc = copy.deepcopy(self.scenarios[self.calls % len(self.scenarios)])
        self.calls += 1
        rng.random()  # consume like a real spawner would
        return sc


def cross_map():
    """Two perpendicular two-lane roads crossing at the origin, road edges, a traffic light on
    each approach of the east-west road (group 0) and the north-south road (group 1), and a
    crosswalk: a small map with every segment type."""
    from selfplaydrive.maps import (
        CrosswalkElement,
        LaneElement,
        MapElements,
        PolylineElement,
        TrafficLightElement,
        compile_map,
    )

    w, L = 3.5, 150.0
    lanes = [
        LaneElement(np.array([[-L, -w / 2], [L, -w / 2]]), width=w, speed_limit=13.9, source_id="east"),
        LaneElement(np.array([[L, w / 2], [-L, w / 2]]), width=w, speed_limit=13.9, source_id="west"),
        LaneElement(np.array([[w / 2, -L], [w / 2, L]]), width=w, speed_limit=13.9, source_id="north"),
        LaneElement(np.array([[-w / 2, L], [-w / 2, -L]]), width=w, speed_limit=13.9, source_id="south"),
    ]
    edges = []
    for sx in (-1, 1):
        for sy in (-1, 1):
            edges.append(
                PolylineElement(
                    np.array([[sx * L, sy * w], [sx * w, sy * w], [sx * w, sy * L]]),
                    source_id=f"edge{sx}{sy}",
                )
            )
    lights = [
        TrafficLightElement(
            np.array([[-w - 1, -w], [-w - 1, 0.0]]), signal_group=0, lanes=[0], source_id="tl_e"
        ),
        TrafficLightElement(
            np.array([[w + 1, w], [w + 1, 0.0]]), signal_group=0, lanes=[1], source_id="tl_w"
        ),
        TrafficLightElement(
            np.array([[0.0, -w - 1], [w, -w - 1]]), signal_group=1, lanes=[2], source_id="tl_n"
        ),
    ]
    walks = [CrosswalkElement(np.array([[10.0, -w], [13.0, -w], [13.0, w], [10.0, w]]), source_id="cw")]
    return compile_map(
        MapElements(name="cross", lanes=lanes, road_edges=edges, traffic_lights=lights, crosswalks=walks)
    )


class RandomSpawner:
    """Random but seeded scenarios on any map: agents near lane centres with random headings
    and speeds, statics, walking pedestrians, random lights. Used where the tests must not
    depend on the project's spawner."""

    def __init__(self, A: int = 8, S: int = 4, P: int = 3, K: int = 4, T: int = 3) -> None:
        self.A, self.S, self.P, self.K, self.T = A, S, P, K, T

    def sample(self, road_map, rng, map_index: int = 0) -> Scenario:
        pts = road_map.lanes.centerlines.points.astype(np.float64)
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        centre = (lo + hi) / 2

        def around(n, spread):
            return centre + rng.uniform(-spread, spread, size=(n, 2))

        nA = int(rng.integers(1, self.A + 1))
        agents = []
        for xy in around(nA, 40.0):
            wps = xy + rng.uniform(-60, 60, size=(int(rng.integers(0, self.K + 1)), 2))
            agents.append(
                dict(
                    xy=xy,
                    heading=rng.uniform(-np.pi, np.pi),
                    speed=rng.uniform(0, 15),
                    length=rng.uniform(1.8, 12),
                    width=rng.uniform(0.6, 2.6),
                    waypoints=wps,
                    coeffs=dict(
                        collision=rng.uniform(0, 1),
                        offroad=rng.uniform(0, 1),
                        center_bias=rng.uniform(-0.3, 0.3),
                    ),
                    hidden=(rng.uniform(0.7, 1.3), rng.uniform(0.9, 1.1), rng.uniform(0.9, 1.1)),
                )
            )
        statics = [
            dict(xy=xy, heading=rng.uniform(-np.pi, np.pi))
            for xy in around(int(rng.integers(0, self.S + 1)), 50.0)
        ]
        peds = [
            dict(
                path=[xy, xy + rng.uniform(-10, 10, 2), xy + rng.uniform(-10, 10, 2)],
                speed=rng.uniform(0.5, 2),
                start=rng.uniform(0, 3),
            )
            for xy in around(int(rng.integers(0, self.P + 1)), 30.0)
        ]
        G = road_map.num_signal_groups
        lights = (
            [(int(rng.integers(0, 4)), float(rng.uniform(0.5, 10))) for _ in range(G)]
            if rng.random() < 0.5
            else []
        )
        sc = make_scenario(
            agents,
            A=self.A,
            S=self.S,
            P=self.P,
            K=self.K,
            T=self.T,
            statics=statics,
            peds=peds,
            lights=lights,
            episode_length=float(rng.choice([2.0, 3.0, 4.0])),
            map_index=map_index,
        )
        if not lights and G:
            sc.light_state = np.zeros(G, np.int8)
            sc.light_time_left = np.ones(G, np.float32)
        return sc
