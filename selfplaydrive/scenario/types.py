"""`Scenario`: the initial state of one world, produced by a spawner (paper section 2.2).

A spawner reads a `RoadMap` and a seeded `numpy.random.Generator` and returns one `Scenario`
per world reset; the simulator packs it into its preallocated buffers. All positions are
float32 metres in the map's local frame (`RoadMap` coordinates), headings are radians
counter-clockwise from +x, speeds m/s.

Slot counts are fixed per env (`num_agents`, `num_static`, `num_pedestrians`); a scenario
may fill fewer slots and marks the rest invalid with the `*_valid` masks.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# Order of the per-agent reward/conditioning coefficients (section 2.3). The observation
# exposes them to the policy in this order; `HIDDEN_PARAMS` are never observed (section 2.6).
COEFF_NAMES = (
    "waypoint_radius",  # D [m]: a waypoint counts as reached within this distance
    "collision",  # C_collision
    "offroad",  # C_offroad
    "red_light",  # C_red
    "comfort",  # C_comfort
    "center",  # C_center
    "center_bias",  # B [m], positive = right of the lane centre
    "align",  # C_align
)
HIDDEN_PARAMS = ("friction", "accel_gain", "steer_gain")


@dataclass
class Scenario:
    """Initial state of one world. A = agents, S = static vehicles, P = pedestrians,
    K = max waypoints, T = max points per pedestrian path, G = signal groups of the map.

    Attributes:
        map_index: Which map of the env this world uses.
        region: (4,) float32 [m] xmin, ymin, xmax, ymax of the world's region.
        agent_valid: (A,) bool, slot holds an agent.
        agent_xy: (A, 2) float32 [m] box centre.
        agent_heading: (A,) float32 [rad].
        agent_speed: (A,) float32 [m/s] initial speed along the heading.
        agent_length: (A,) float32 [m].
        agent_width: (A,) float32 [m].
        agent_parked: (A,) bool, started parked at the roadside (still policy-controlled).
        agent_lane: (A,) int32 lane the agent started on (-1 when parked off-lane).
        waypoints: (A, K, 2) float32 [m] route waypoints, padded with the last valid one.
        num_waypoints: (A,) int32 number of valid waypoints (0..K).
        coeffs: (A, len(COEFF_NAMES)) float32 reward coefficients, order `COEFF_NAMES`.
        hidden: (A, len(HIDDEN_PARAMS)) float32 friction mu and action gains (not observed).
        static_valid: (S,) bool.
        static_xy: (S, 2) float32 [m].
        static_heading: (S,) float32 [rad].
        static_length: (S,) float32 [m].
        static_width: (S,) float32 [m].
        ped_valid: (P,) bool.
        ped_path: (P, T, 2) float32 [m] polyline each pedestrian walks, padded with its last point.
        ped_num_points: (P,) int32 valid points of each path (>= 2 when valid).
        ped_speed: (P,) float32 [m/s] walking speed along the path.
        ped_start_time: (P,) float32 [s] time the pedestrian starts walking (waits before).
        ped_size: (P, 2) float32 [m] length, width of the pedestrian box.
        lights_enabled: False in the episodes where every light is off.
        light_state: (G,) int8 initial state per signal group: 0 off, 1 red, 2 yellow, 3 green.
        light_time_left: (G,) float32 [s] until the group's next change.
        episode_length: [s], one of the configured lengths (20, 30 or 40 by default).
    """

    map_index: int
    region: np.ndarray
    agent_valid: np.ndarray
    agent_xy: np.ndarray
    agent_heading: np.ndarray
    agent_speed: np.ndarray
    agent_length: np.ndarray
    agent_width: np.ndarray
    agent_parked: np.ndarray
    agent_lane: np.ndarray
    waypoints: np.ndarray
    num_waypoints: np.ndarray
    coeffs: np.ndarray
    hidden: np.ndarray
    static_valid: np.ndarray
    static_xy: np.ndarray
    static_heading: np.ndarray
    static_length: np.ndarray
    static_width: np.ndarray
    ped_valid: np.ndarray
    ped_path: np.ndarray
    ped_num_points: np.ndarray
    ped_speed: np.ndarray
    ped_start_time: np.ndarray
    ped_size: np.ndarray
    lights_enabled: bool
    light_state: np.ndarray
    light_time_left: np.ndarray
    episode_length: float

    @classmethod
    def empty(
        cls,
        num_agents: int,
        max_waypoints: int,
        num_static: int,
        num_pedestrians: int,
        path_points: int,
        num_groups: int,
        map_index: int = 0,
        region: np.ndarray | None = None,
        episode_length: float = 0.0,
    ) -> Scenario:
        """A scenario with every slot invalid and zero-filled (the padding convention), lights
        off; spawners and scenario suites fill in the slots they use."""
        a, k, s, p, f4 = num_agents, max_waypoints, num_static, num_pedestrians, np.float32
        # np.empty + fill: np.full costs several times more for these small arrays (a reset
        # builds one Scenario)
        agent_lane = np.empty(a, np.int32)
        agent_lane.fill(-1)
        light_time_left = np.empty(num_groups, f4)
        light_time_left.fill(episode_length)
        return cls(
            map_index=int(map_index),
            region=np.zeros(4, f4) if region is None else np.asarray(region, f4),
            agent_valid=np.zeros(a, bool),
            agent_xy=np.zeros((a, 2), f4),
            agent_heading=np.zeros(a, f4),
            agent_speed=np.zeros(a, f4),
            agent_length=np.zeros(a, f4),
            agent_width=np.zeros(a, f4),
            agent_parked=np.zeros(a, bool),
            agent_lane=agent_lane,
            waypoints=np.zeros((a, k, 2), f4),
            num_waypoints=np.zeros(a, np.int32),
            coeffs=np.zeros((a, len(COEFF_NAMES)), f4),
            hidden=np.zeros((a, len(HIDDEN_PARAMS)), f4),
            static_valid=np.zeros(s, bool),
            static_xy=np.zeros((s, 2), f4),
            static_heading=np.zeros(s, f4),
            static_length=np.zeros(s, f4),
            static_width=np.zeros(s, f4),
            ped_valid=np.zeros(p, bool),
            ped_path=np.zeros((p, path_points, 2), f4),
            ped_num_points=np.zeros(p, np.int32),
            ped_speed=np.zeros(p, f4),
            ped_start_time=np.zeros(p, f4),
            ped_size=np.zeros((p, 2), f4),
            lights_enabled=False,
            light_state=np.zeros(num_groups, np.int8),
            light_time_left=light_time_left,
            episode_length=float(episode_length),
        )
