"""`PaperSpawner`: the initial state of one world as in paper section 2.2.

Steps of `PaperSpawner.sample` (all randomness from the `rng` passed in, in a fixed order, so
the same seed gives the same `Scenario`):

1. Region: a 200 x 200 m square around a random candidate centre with enough spawnable lane
   (`MapIndex.centres`), jittered by +-stride/2.
2. Agents: Binomial(num_agents, parked_share) of them are parked: placed beside a rightmost
   lane, right side `curb_gap` inside the road edge, heading along the lane, speed 0. The rest
   are aligned: on a vehicle lane outside junctions, heading = lane direction + U(-h, h),
   lateral shift U(-l, l) (kept inside the lane), speed U(initial_speed) capped by the lane's
   speed limit. Any two agents are at least `min_agent_distance` (15 m) apart (box centres).
   Candidates are drawn one at a time and accepted greedily (`_sim.placement.Placer.agents`); their
   number is bounded (`candidates_per_agent` per wanted agent; the aligned agents' first
   `first_round_candidates` per agent are drawn in one block), so infeasible settings never
   hang: the world gets fewer agents and a `UserWarning` names the shortfall (once per spawner
   and map; every shortfall is counted in `PaperSpawner.shortfalls` and `missing_agents`).
   Parked slots that find no roadside become aligned agents; slots are shuffled so parked
   agents are spread over them.
3. Waypoints: a random legal route from each agent's lane (`maps.routing.sample_routes`) and up
   to `max_waypoints` waypoints on average `waypoint_spacing` s apart at the speed limit.
4. Static vehicles: U{static_count} parked vehicles at the roadside, not overlapping agents
   or each other (bounding circles + `static_gap`), out of the lane space right ahead of every
   agent (its box grown by `static_gap`, stretched forward by `STATIC_CLEAR_AHEAD` = 5 m plus
   the distance it covers in `STATIC_HEADWAY` = 1 s), each leaving at least
   `min_free_lane_width` of its lane free (`_sim.placement.Placer.statics`).
   With `turn_lane_starts` > 0 (off in the paper), up to that many driving agents are then
   moved to turn-lane starts (`scenario.turn_starts.TurnLaneStarts`); with `turn_lane_worlds`
   > 0 that share of worlds holds turn-lane starts only.
5. Pedestrians crossing at crosswalks and elsewhere (`PedestrianSampler`).
6. Traffic lights (`LightSampler`), episode length from `episode_lengths`, per-agent reward
   coefficients (`ConditioningSampler`) and hidden dynamics parameters (`HiddenParamSampler`).
"""

from __future__ import annotations

import warnings
import weakref
from collections.abc import MutableMapping, Sequence

import numpy as np

from selfplaydrive._sim.placement import Placer
from selfplaydrive.errors import ConfigError
from selfplaydrive.maps.roadmap import RoadMap
from selfplaydrive.maps.routing import MIN_CHANGE_LENGTH
from selfplaydrive.scenario.conditioning import ConditioningSampler, HiddenParamSampler
from selfplaydrive.scenario.index import MapIndex, map_index
from selfplaydrive.scenario.lights import LightSampler
from selfplaydrive.scenario.pedestrians import PATH_POINTS, PedestrianSampler
from selfplaydrive.scenario.placement import sample_region
from selfplaydrive.scenario.turn_starts import TurnLaneStarts
from selfplaydrive.scenario.types import Scenario
from selfplaydrive.scenario.vehicles import VehicleSizeSampler

# `PaperSpawner` options that are training curricula, not part of the world (off in the paper),
# with their "off" values: evaluations of a policy in its training spawner switch them off
# (`without_curricula`), so a run trained with turn-lane worlds is not scored on them.
CURRICULUM_OPTIONS = {"turn_lane_starts": 0, "turn_lane_worlds": 0.0}


def without_curricula(spawner_cfg: MutableMapping) -> MutableMapping:
    """Set every `CURRICULUM_OPTIONS` key present in a spawner config (a dict or an OmegaConf
    node of `PaperSpawner` arguments) to its "off" value, in place; returns it."""
    for key, off in CURRICULUM_OPTIONS.items():
        if key in spawner_cfg:
            spawner_cfg[key] = off
    return spawner_cfg


# pieces per route at most (the default of `maps.routing.sample_routes`)
MAX_ROUTE_PIECES = 128
# columns of the placement kernel's agent rows (`_sim.placement.Placer`, its NumPy reference)
AGENT_COLUMNS = ("lane", "s", "x", "y", "heading", "speed", "length", "width", "parked", "on_lane")
# A static vehicle keeps out of the lane space ahead of each agent: STATIC_CLEAR_AHEAD m (one
# car length) plus the distance the agent covers in STATIC_HEADWAY s at its initial speed, so
# none stands right in front of an agent at the start
STATIC_CLEAR_AHEAD = 5.0  # [m]
STATIC_HEADWAY = 1.0  # [s]


class PaperSpawner:
    """Spawner of paper section 2.2 (see the module docstring for the steps).

    Slot sizes are constructor arguments (the env's fixed buffer sizes); a scenario fills up to
    them and marks the rest invalid. The placement settings and size samplers are bound to the
    placement kernel at construction: change them by building a new spawner.

    Args:
        num_agents: A, agent slots; the spawner tries to fill all of them (32 in the paper).
        num_static: S, static-vehicle slots (48).
        num_pedestrians: P, pedestrian slots.
        max_waypoints: K, waypoint slots per agent (8).
        region_size: Edge of the square spawn region [m] (200).
        region_stride: Spacing of the candidate region centres [m].
        min_region_lane_length: Spawnable lane length [m] a candidate region needs.
        min_agent_distance: Minimum distance between agent box centres [m] (15).
        parked_share: Probability an agent starts parked at the roadside (0.1).
        initial_speed: (low, high) [m/s] uniform initial speed of aligned agents, capped by
            the lane speed limit.
        heading_noise: h [rad]; aligned headings get U(-h, h) added.
        lateral_noise: l [m]; aligned agents are shifted U(-l, l) sideways, limited so the
            box stays inside the lane width.
        candidates_per_agent: Candidate poses drawn per wanted agent at most (bounds the work
            when the spacing cannot be met).
        first_round_candidates: Candidates per agent of the first round; the rest of the budget
            is drawn only when the first round falls short.
        static_candidates_per_vehicle: Candidate roadside spots drawn per wanted static vehicle.
        static_count: (low, high) inclusive number of static vehicles; None = (0, num_static).
        static_gap: Clearance [m] between static vehicles' bounding circles and other vehicles.
        min_free_lane_width: Lane width [m] a static vehicle must leave free.
        curb_gap: Distance [m] between a parked vehicle's right side and the road edge.
        max_shoulder: Where no road edge is near, how far [m] beyond the lane border a parked
            vehicle's right side may go.
        waypoint_spacing: Mean time between waypoints at the speed limit [s] (5).
        waypoint_spacing_jitter: Gaps are spacing * U(1 - j, 1 + j).
        lane_change_prob: Probability of a legal lane change per route step.
        turn_lane_starts: Driving agents per world moved to a start of the turn-lane suite
            (`scenario.turn_starts`: on a lane from which the coming turn is not legal, only
            waypoints after the junction), a training curriculum for section 5.3; 0 = off (the
            paper's spawner; no extra random draws).
        turn_lane_worlds: Probability that a world holds turn-lane starts only: every agent is
            moved to one or removed (`TurnLaneStarts.apply(clear=True)`); 0 = off (no draw).
        episode_lengths: Episode lengths [s], drawn uniformly (20, 30, 40).
        sizes: Size sampler of agents (default `VehicleSizeSampler()`).
        static_sizes: Size sampler of static vehicles (default `VehicleSizeSampler()`).
        conditioning: Reward coefficient sampler (default train mode).
        hidden: Hidden dynamics parameter sampler.
        pedestrians: Pedestrian sampler.
        lights: Traffic-light sampler.

    Attributes:
        shortfalls: Map name -> worlds sampled with fewer than `num_agents` agents (only the
            first such world per map warns).
        missing_agents: Map name -> agent slots left empty in those worlds, summed.

    Raises:
        ConfigError: On non-positive slot counts or out-of-range settings.
    """

    def __init__(
        self,
        num_agents: int = 32,
        num_static: int = 48,
        num_pedestrians: int = 8,
        max_waypoints: int = 8,
        region_size: float = 200.0,
        region_stride: float = 20.0,
        min_region_lane_length: float = 1500.0,
        min_agent_distance: float = 15.0,
        parked_share: float = 0.1,
        initial_speed: tuple[float, float] = (0.0, 5.0),
        heading_noise: float = 0.05,
        lateral_noise: float = 0.25,
        candidates_per_agent: int = 32,
        first_round_candidates: int = 4,
        static_candidates_per_vehicle: int = 4,
        static_count: tuple[int, int] | None = None,
        static_gap: float = 1.0,
        min_free_lane_width: float = 1.0,
        curb_gap: float = 0.3,
        max_shoulder: float = 1.0,
        waypoint_spacing: float = 5.0,
        waypoint_spacing_jitter: float = 0.5,
        lane_change_prob: float = 0.1,
        turn_lane_starts: int = 0,
        turn_lane_worlds: float = 0.0,
        episode_lengths: Sequence[float] = (20.0, 30.0, 40.0),
        sizes: VehicleSizeSampler | None = None,
        static_sizes: VehicleSizeSampler | None = None,
        conditioning: ConditioningSampler | None = None,
        hidden: HiddenParamSampler | None = None,
        pedestrians: PedestrianSampler | None = None,
        lights: LightSampler | None = None,
    ) -> None:
        _check_int("num_agents", num_agents, 1)
        _check_int("num_static", num_static, 0)
        _check_int("num_pedestrians", num_pedestrians, 0)
        _check_int("max_waypoints", max_waypoints, 1)
        _check_int("candidates_per_agent", candidates_per_agent, 1)
        _check_int("first_round_candidates", first_round_candidates, 1)
        _check_int("static_candidates_per_vehicle", static_candidates_per_vehicle, 1)
        _check_int("turn_lane_starts", turn_lane_starts, 0)
        if not 0.0 <= turn_lane_worlds <= 1.0:
            raise ConfigError(f"PaperSpawner.turn_lane_worlds must lie in [0, 1], got {turn_lane_worlds}")
        if (turn_lane_starts or turn_lane_worlds) and max_waypoints < 2:
            raise ConfigError(
                f"PaperSpawner.turn_lane_starts={turn_lane_starts} / turn_lane_worlds={turn_lane_worlds} "
                f"give agents two waypoints: max_waypoints must be >= 2, got {max_waypoints}"
            )
        if not 0.0 <= parked_share <= 1.0:
            raise ConfigError(f"PaperSpawner.parked_share must lie in [0, 1], got {parked_share}")
        for name, v in (
            ("region_size", region_size),
            ("region_stride", region_stride),
            ("waypoint_spacing", waypoint_spacing),
        ):
            if not v > 0:
                raise ConfigError(f"PaperSpawner.{name} must be positive, got {v}")
        if region_stride > region_size:
            # centres are jittered by +-stride/2 and lane lengths summed on stride/2 bins: a
            # coarser lattice than the region moves regions off the lanes that qualified them
            raise ConfigError(
                f"PaperSpawner.region_stride must not exceed region_size, got "
                f"region_stride={region_stride} m and region_size={region_size} m"
            )
        if not 0 <= initial_speed[0] <= initial_speed[1]:
            raise ConfigError(
                f"PaperSpawner.initial_speed must satisfy 0 <= low <= high [m/s], got {initial_speed}"
            )
        if not 0.0 <= waypoint_spacing_jitter < 1.0:
            raise ConfigError(
                f"PaperSpawner.waypoint_spacing_jitter must lie in [0, 1), got {waypoint_spacing_jitter}"
            )
        lengths = tuple(float(v) for v in episode_lengths)
        if not lengths or min(lengths) <= 0:
            raise ConfigError(
                f"PaperSpawner.episode_lengths must be positive numbers [s], got {episode_lengths}"
            )
        static_count = (0, num_static) if static_count is None else tuple(int(v) for v in static_count)
        if not 0 <= static_count[0] <= static_count[1]:
            raise ConfigError(f"PaperSpawner.static_count must satisfy 0 <= low <= high, got {static_count}")
        self.num_agents, self.num_static = int(num_agents), int(num_static)
        self.num_pedestrians, self.max_waypoints = int(num_pedestrians), int(max_waypoints)
        self.index_args = {
            "region_size": float(region_size),
            "region_stride": float(region_stride),
            "min_region_lane_length": float(min_region_lane_length),
        }
        self.min_agent_distance = float(min_agent_distance)
        self.parked_share = float(parked_share)
        self.initial_speed = (float(initial_speed[0]), float(initial_speed[1]))
        self.heading_noise, self.lateral_noise = float(heading_noise), float(lateral_noise)
        self.candidates_per_agent = int(candidates_per_agent)
        self.first_round_candidates = int(first_round_candidates)
        self.static_candidates_per_vehicle = int(static_candidates_per_vehicle)
        self.static_count = static_count
        self.static_gap, self.min_free_lane_width = float(static_gap), float(min_free_lane_width)
        self.curb_gap, self.max_shoulder = float(curb_gap), float(max_shoulder)
        self.waypoint_spacing, self.waypoint_spacing_jitter = (
            float(waypoint_spacing),
            float(waypoint_spacing_jitter),
        )
        self.lane_change_prob = float(lane_change_prob)
        self.episode_lengths = lengths
        self.sizes = sizes or VehicleSizeSampler()
        self.static_sizes = static_sizes or VehicleSizeSampler()
        self.conditioning = conditioning or ConditioningSampler()
        self.hidden = hidden or HiddenParamSampler()
        self.pedestrians = pedestrians or PedestrianSampler()
        self.lights = lights or LightSampler()
        self.turn_lane_starts, self.turn_lane_worlds = int(turn_lane_starts), float(turn_lane_worlds)
        self._turn_starts: TurnLaneStarts | None = None  # built when first used
        # spawn shortfalls (worlds that got fewer than num_agents agents): the first one per map
        # warns, every one is counted here
        self.shortfalls: dict[str, int] = {}
        self.missing_agents: dict[str, int] = {}
        self._last_index: tuple[weakref.ref, MapIndex] | None = None  # prepare's last map
        # the settings above bound once for the placement kernel
        self._placer = Placer(
            self.sizes, self.static_sizes, self.min_agent_distance, self.first_round_candidates,
            self.candidates_per_agent, self.static_candidates_per_vehicle, self.lateral_noise,
            self.heading_noise, self.initial_speed[0], self.initial_speed[1], self.curb_gap,
            self.max_shoulder, self.static_gap, self.min_free_lane_width, STATIC_CLEAR_AHEAD, STATIC_HEADWAY,
        )  # fmt: skip

    def prepare(self, road_map: RoadMap) -> MapIndex:
        """Build (or fetch from the cache) the per-map tables; call once per map up front."""
        last = self._last_index
        if last is not None and last[0]() is road_map:
            return last[1]
        index = map_index(road_map, **self.index_args)
        self._last_index = (weakref.ref(road_map), index)
        return index

    def sample(self, road_map: RoadMap, rng: np.random.Generator, map_index: int = 0) -> Scenario:
        """Sample the initial state of one world.

        Args:
            road_map: The world's map.
            rng: Seeded generator; the same seed gives an identical `Scenario`.
            map_index: Index of `road_map` among the env's maps (stored in the scenario).

        Raises:
            ValueError: When the map has no spawnable lane (vehicle or bus lane outside junctions).
            ConfigError: When not even one agent fits in the sampled region.

        Warns:
            UserWarning: When fewer than `num_agents` agents could be placed.
        """
        index = self.prepare(road_map)
        box = sample_region(index, rng)
        groups = index.num_signal_groups
        sc = _empty_scenario(self, map_index, box, groups)
        lane, s = self._agents(sc, index, box, rng)
        n = len(lane)
        self._waypoints(sc, index, lane, s, rng)
        veh_xy, veh_r, still = self._statics(sc, index, box, rng, n)
        # the options, not the table, decide: `scenario.protocol.paper_protocol` turns them off
        # on a built spawner, which then draws exactly what one built with them off draws
        if (self.turn_lane_starts or self.turn_lane_worlds) and self._move_to_turn_starts(sc, road_map, rng):
            veh_xy[:n] = sc.agent_xy[:n]  # the pedestrians keep clear of the moved agents
        peds = self.pedestrians.sample(
            rng, index.crossings, index.crosswalks, box, self.num_pedestrians, veh_xy, veh_r, still
        )
        sc.ped_valid, sc.ped_path, sc.ped_num_points = peds.valid, peds.path, peds.num_points
        sc.ped_speed, sc.ped_start_time, sc.ped_size = peds.speed, peds.start_time, peds.size
        sc.episode_length = self.episode_lengths[int(rng.integers(len(self.episode_lengths)))]
        sc.lights_enabled, sc.light_state, sc.light_time_left = self.lights.sample(
            rng, groups, sc.episode_length
        )
        sc.coeffs[:n] = self.conditioning.sample(rng, n)
        sc.hidden[:n] = self.hidden.sample(rng, n)
        return sc

    def _move_to_turn_starts(self, sc: Scenario, road_map: RoadMap, rng: np.random.Generator) -> int:
        """Turn-lane starts (`scenario.turn_starts`): a whole turn-lane world with probability
        `turn_lane_worlds` (one draw, only when it is > 0), else `turn_lane_starts` agents."""
        if self._turn_starts is None:
            self._turn_starts = TurnLaneStarts(
                min_agent_distance=self.min_agent_distance, static_gap=self.static_gap
            )
        if self.turn_lane_worlds > 0 and rng.random() < self.turn_lane_worlds:
            return self._turn_starts.apply(sc, road_map, rng, self.num_agents, clear=True)
        return self._turn_starts.apply(sc, road_map, rng, self.turn_lane_starts)

    # -- agents ---------------------------------------------------------------------------------

    def _agents(
        self, sc: Scenario, index: MapIndex, box: np.ndarray, rng: np.random.Generator
    ) -> tuple[np.ndarray, np.ndarray]:
        """Place parked then aligned agents, 15 m apart, into the agent slots of `sc`
        (`_sim.placement.Placer.agents`); returns each agent's route start: lane (n,) int64 and
        arc length (n,) float64 [m], in slot order."""
        want = self.num_agents
        n_parked = int(rng.binomial(want, self.parked_share))
        k = index.kernels
        got, _, lane, s = self._placer.agents(k.spawn, k.roadside, rng, box, want, n_parked, sc)
        if got == 0:
            raise ConfigError(
                f"PaperSpawner could not place a single agent on map {index.road_map.name!r} in region "
                f"{np.round(box, 1).tolist()}: the map has no spawnable lane there"
            )
        if got < want:
            self._shortfall(index.road_map.name, got, want)
        return lane, s

    def _shortfall(self, name: str, got: int, want: int) -> None:
        """Count a world spawned with `got` < `want` agents; warn only on the first per map."""
        first = name not in self.shortfalls
        self.shortfalls[name] = self.shortfalls.get(name, 0) + 1
        self.missing_agents[name] = self.missing_agents.get(name, 0) + want - got
        if first:
            warnings.warn(
                f"PaperSpawner placed {got} of num_agents={want} agents on map {name!r}: "
                f"min_agent_distance={self.min_agent_distance} m could not be met within "
                f"candidates_per_agent={self.candidates_per_agent} candidates per agent; further "
                f"shortfalls on this map are not warned but counted in PaperSpawner.shortfalls "
                f"(worlds) and PaperSpawner.missing_agents (agents)",
                UserWarning,
                stacklevel=4,
            )

    def _waypoints(
        self, sc: Scenario, index: MapIndex, lane: np.ndarray, s: np.ndarray, rng: np.random.Generator
    ) -> None:
        """Random legal routes from (lane, s) and up to K waypoints along them (section 2.2):
        `maps.routing.waypoint_times`, the key `sample_routes` draws, `sample_routes` and
        `batch_waypoints` (same draws, same results) fused in one kernel call
        (`_sim.waypoints.RouteKernel.draw_waypoints`)."""
        index.kernels.routes.draw_waypoints(
            rng,
            lane,
            s,
            self.max_waypoints,
            self.waypoint_spacing,
            self.waypoint_spacing_jitter,
            self.lane_change_prob,
            MIN_CHANGE_LENGTH,
            MAX_ROUTE_PIECES,
            sc.waypoints,
            sc.num_waypoints,
        )

    # -- static vehicles ------------------------------------------------------------------------

    def _statics(
        self, sc: Scenario, index: MapIndex, box: np.ndarray, rng: np.random.Generator, n_agents: int
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Up to `static_count` stationary vehicles at the roadside, clear of every agent
        (`_sim.placement.Placer.statics`). Returns every vehicle of the world (agents, then static
        vehicles): centres (n, 2) [m], bounding-circle radii (n,) [m] and whether each stands
        still (parked agent or static vehicle), for the pedestrians."""
        lo, hi = self.static_count
        want = min(int(rng.integers(lo, hi + 1)), self.num_static)
        _, xy, radius, still = self._placer.statics(index.kernels.roadside, rng, box, want, n_agents, sc)
        return xy, radius, still


def _check_int(name: str, value: int, minimum: int) -> None:
    if int(value) != value or value < minimum:
        raise ConfigError(f"PaperSpawner.{name} must be an integer >= {minimum}, got {value!r}")


def _empty_scenario(sp: PaperSpawner, map_index: int, box: np.ndarray, groups: int) -> Scenario:
    """A Scenario with every slot invalid and zero-filled (the padding convention)."""
    return Scenario.empty(
        sp.num_agents,
        sp.max_waypoints,
        sp.num_static,
        sp.num_pedestrians,
        PATH_POINTS,
        groups,
        map_index,
        box,
    )
