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
   Candidates are accepted greedily in random order; their number is bounded (a first round of
   `first_round_candidates` per wanted agent, a second up to `candidates_per_agent` in all only
   when the first falls short), so infeasible settings never hang: the world gets fewer agents
   and a `UserWarning` names the shortfall (once per spawner and map; every shortfall is
   counted in `PaperSpawner.shortfalls` and `missing_agents`). Parked slots that find no
   roadside become aligned agents; slots are shuffled so parked agents are spread over them.
3. Waypoints: a random legal route from each agent's lane (`maps.routing.sample_routes`) and up
   to `max_waypoints` waypoints on average `waypoint_spacing` s apart at the speed limit.
4. Static vehicles: U{static_count} parked vehicles at the roadside, not overlapping agents
   or each other (bounding circles + `static_gap`), each leaving at least
   `min_free_lane_width` of its lane free.
5. Pedestrians crossing at crosswalks and elsewhere (`PedestrianSampler`).
6. Traffic lights (`LightSampler`), episode length from `episode_lengths`, per-agent reward
   coefficients (`ConditioningSampler`) and hidden dynamics parameters (`HiddenParamSampler`).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np

from selfplaydrive._sim.spawn import aligned_candidates, roadside_poses
from selfplaydrive.errors import ConfigError
from selfplaydrive.maps.roadmap import RoadMap
from selfplaydrive.maps.routing import MIN_CHANGE_LENGTH, waypoint_times
from selfplaydrive.scenario.conditioning import ConditioningSampler, HiddenParamSampler
from selfplaydrive.scenario.index import MapIndex, map_index
from selfplaydrive.scenario.lights import LightSampler
from selfplaydrive.scenario.pedestrians import PATH_POINTS, PedestrianSampler
from selfplaydrive.scenario.placement import Poses, sample_on_chunks, sample_region
from selfplaydrive.scenario.placement import greedy_separated as _greedy
from selfplaydrive.scenario.types import Scenario
from selfplaydrive.scenario.vehicles import VehicleSizeSampler

# pieces per route at most (the default of `maps.routing.sample_routes`)
MAX_ROUTE_PIECES = 128
# columns of the spawner's (n, 10) agent rows
AGENT_COLUMNS = ("lane", "s", "x", "y", "heading", "speed", "length", "width", "parked", "on_lane")


def _half_diag(length: np.ndarray, width: np.ndarray) -> np.ndarray:
    return 0.5 * np.hypot(length, width)


class PaperSpawner:
    """Spawner of paper section 2.2 (see the module docstring for the steps).

    Slot sizes are constructor arguments (the env's fixed buffer sizes); a scenario fills up to
    them and marks the rest invalid.

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
        if not 0.0 <= parked_share <= 1.0:
            raise ConfigError(f"PaperSpawner.parked_share must lie in [0, 1], got {parked_share}")
        for name, v in (
            ("region_size", region_size),
            ("region_stride", region_stride),
            ("waypoint_spacing", waypoint_spacing),
        ):
            if not v > 0:
                raise ConfigError(f"PaperSpawner.{name} must be positive, got {v}")
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
        # spawn shortfalls (worlds that got fewer than num_agents agents): the first one per map
        # warns, every one is counted here
        self.shortfalls: dict[str, int] = {}
        self.missing_agents: dict[str, int] = {}

    def prepare(self, road_map: RoadMap) -> MapIndex:
        """Build (or fetch from the cache) the per-map tables; call once per map up front."""
        return map_index(road_map, **self.index_args)

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
        sc = _empty_scenario(self, map_index, box, road_map.num_signal_groups)
        agents = self._agents(index, box, rng)
        n = len(agents)
        self._write_agents(sc, agents)
        self._waypoints(sc, index, agents[:, 0].astype(np.int64), agents[:, 1], rng)
        veh_xy, veh_r = agents[:, 2:4], _half_diag(agents[:, 6], agents[:, 7])
        self._statics(sc, index, box, rng, veh_xy, veh_r)
        m = int(sc.static_valid.sum())
        all_xy = np.concatenate([veh_xy, sc.static_xy[:m].astype(np.float64)])
        all_r = np.concatenate([veh_r, _half_diag(sc.static_length[:m], sc.static_width[:m])])
        still = np.concatenate([agents[:, 8] != 0, np.ones(m, dtype=bool)])
        peds = self.pedestrians.sample(
            rng, index.crossings, index.crosswalks, box, self.num_pedestrians, all_xy, all_r, still
        )
        sc.ped_valid, sc.ped_path, sc.ped_num_points = peds.valid, peds.path, peds.num_points
        sc.ped_speed, sc.ped_start_time, sc.ped_size = peds.speed, peds.start_time, peds.size
        sc.episode_length = self.episode_lengths[int(rng.integers(len(self.episode_lengths)))]
        sc.lights_enabled, sc.light_state, sc.light_time_left = self.lights.sample(
            rng, road_map.num_signal_groups, sc.episode_length
        )
        sc.coeffs[:n] = self.conditioning.sample(rng, n)
        sc.hidden[:n] = self.hidden.sample(rng, n)
        return sc

    # -- agents ---------------------------------------------------------------------------------
    # Agents and candidates are rows of one (n, 10) float64 array, columns `AGENT_COLUMNS`
    # (lane index, arc length, centre x and y, heading, speed, length, width, parked, on lane),
    # so a selection is one indexing operation.

    def _agents(self, index: MapIndex, box: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Place parked then aligned agents, 15 m apart; returns (n, 10) rows in slot order."""
        want = self.num_agents
        n_parked = int(rng.binomial(want, self.parked_share))
        parked = self._parked(index, box, rng, n_parked)
        aligned = self._spaced_aligned(index, box, rng, parked[:, 2:4], want - len(parked))
        out = np.concatenate([parked, aligned])
        got = len(out)
        if got == 0:
            raise ConfigError(
                f"PaperSpawner could not place a single agent on map {index.road_map.name!r} in region "
                f"{np.round(box, 1).tolist()}: the map has no spawnable lane there"
            )
        if got < want:
            self._shortfall(index.road_map.name, got, want)
        order = rng.permutation(got)  # mix parked and aligned agents over the slots
        return out[order]

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

    def _spaced_aligned(
        self, index: MapIndex, box: np.ndarray, rng: np.random.Generator, fixed_xy: np.ndarray, need: int
    ) -> np.ndarray:
        """Aligned agents `min_agent_distance` apart from each other and from `fixed_xy` (final
        positions, lateral shift included), drawn in two rounds: first `first_round_candidates`
        per agent, then the rest of the `candidates_per_agent` budget only if that fell short."""
        radius = self.min_agent_distance / 2
        first = min(self.first_round_candidates, self.candidates_per_agent)
        cand = self._aligned(index, sample_on_chunks(index, index.spawn, box, rng, need * first), rng)
        fixed_r = np.full(len(fixed_xy), radius)
        picked = _greedy(cand[:, 2:4], np.full(len(cand), radius), need, fixed_xy, fixed_r)
        if len(picked) < need and self.candidates_per_agent > first:
            more = sample_on_chunks(index, index.spawn, box, rng, need * (self.candidates_per_agent - first))
            cand = np.concatenate([cand, self._aligned(index, more, rng)])
            picked = _greedy(cand[:, 2:4], np.full(len(cand), radius), need, fixed_xy, fixed_r)
        return cand[picked]

    def _parked(self, index: MapIndex, box: np.ndarray, rng: np.random.Generator, n: int) -> np.ndarray:
        """Up to n parked agents at roadside spots, `min_agent_distance` apart (section 2.2)."""
        cand = sample_on_chunks(index, index.roadside, box, rng, n * self.candidates_per_agent)
        length, width, _ = self.sizes.sample(rng, len(cand.lane))
        xy, off, _ = self._roadside(index, cand, width, 0.0)
        k = _greedy(xy, np.full(len(xy), self.min_agent_distance / 2), n)
        out = np.empty((len(k), len(AGENT_COLUMNS)))
        out[:, 0] = cand.lane[k]
        out[:, 1] = cand.s[k]
        out[:, 2:4] = xy[k]
        out[:, 4] = cand.heading[k]
        out[:, 5] = 0.0
        out[:, 6] = length[k]
        out[:, 7] = width[k]
        out[:, 8] = 1.0
        out[:, 9] = off[k] <= index.road_map.lanes.width[cand.lane[k]].astype(np.float64) / 2
        return out

    def _roadside(
        self, index: MapIndex, cand: Poses, width: np.ndarray, min_free: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Roadside poses of vehicles of `width` parked at the candidates (`roadside_offset`
        then `offset_right`, kernel `_sim.spawn.roadside_poses`): centres (n, 2), lateral
        offsets (n,) and whether each leaves `min_free` m of its lane free."""
        n = len(cand.lane)
        xy, off, fits = np.empty((n, 2)), np.empty(n), np.empty(n, dtype=bool)
        roadside_poses(
            cand.lane, cand.chunk, cand.xy, np.sin(cand.heading), np.cos(cand.heading), width,
            index.road_map.lanes.width, index.roadside.edge, self.curb_gap, self.max_shoulder,
            min_free, xy, off, fits,
        )  # fmt: skip
        return xy, off, fits

    def _aligned(self, index: MapIndex, poses: Poses, rng: np.random.Generator) -> np.ndarray:
        """Aligned-agent candidates at `poses`: sizes, lateral shift, heading noise, speed
        (kernel `_sim.spawn.aligned_candidates`); (n, 10) rows."""
        n = len(poses.lane)
        length, width, _ = self.sizes.sample(rng, n)
        u = rng.random((3, n))
        lanes = index.road_map.lanes
        out = np.empty((n, len(AGENT_COLUMNS)))
        lo, hi = self.initial_speed
        aligned_candidates(
            poses.lane, poses.s, poses.xy, poses.heading, np.sin(poses.heading), np.cos(poses.heading),
            length, width, u, lanes.width, lanes.speed_limit, self.lateral_noise, self.heading_noise,
            lo, hi, out,
        )  # fmt: skip
        return out

    @staticmethod
    def _write_agents(sc: Scenario, a: np.ndarray) -> None:
        n = len(a)
        sc.agent_valid[:n] = True
        sc.agent_xy[:n] = a[:, 2:4]
        sc.agent_heading[:n] = a[:, 4]
        sc.agent_speed[:n] = a[:, 5]
        sc.agent_length[:n] = a[:, 6]
        sc.agent_width[:n] = a[:, 7]
        sc.agent_parked[:n] = a[:, 8] != 0
        sc.agent_lane[:n] = np.where(a[:, 9] != 0, a[:, 0], -1)

    def _waypoints(
        self, sc: Scenario, index: MapIndex, lane: np.ndarray, s: np.ndarray, rng: np.random.Generator
    ) -> None:
        """Random legal routes from (lane, s) and up to K waypoints along them (section 2.2):
        `maps.routing.sample_routes` + `batch_waypoints` (same draws, same results) fused in
        one kernel call (`_sim.spawn.RouteKernel.waypoints`)."""
        n = len(lane)
        times = waypoint_times(
            rng, n, self.max_waypoints, self.waypoint_spacing, self.waypoint_spacing_jitter
        )
        key = int(rng.integers(0, 2**63))  # the key sample_routes draws
        index.kernels.routes.waypoints(
            np.ascontiguousarray(lane, dtype=np.int64),
            np.ascontiguousarray(s, dtype=np.float64),
            times,
            key,
            self.lane_change_prob,
            MIN_CHANGE_LENGTH,
            MAX_ROUTE_PIECES,
            sc.waypoints,
            sc.num_waypoints,
        )

    # -- static vehicles ------------------------------------------------------------------------

    def _statics(
        self,
        sc: Scenario,
        index: MapIndex,
        box: np.ndarray,
        rng: np.random.Generator,
        veh_xy: np.ndarray,
        veh_r: np.ndarray,
    ) -> None:
        """Up to `static_count` stationary vehicles at the roadside, clear of every agent."""
        lo, hi = self.static_count
        want = min(int(rng.integers(lo, hi + 1)), self.num_static)
        if want == 0:
            return
        cand = sample_on_chunks(index, index.roadside, box, rng, want * self.static_candidates_per_vehicle)
        length, width, _ = self.static_sizes.sample(rng, len(cand.lane))
        # section 2.2: stationary vehicles must not block a lane completely
        xy, _, fits = self._roadside(index, cand, width, self.min_free_lane_width)
        keep = np.flatnonzero(fits)
        xy = xy[keep]
        r = _half_diag(length[keep], width[keep])
        k = _greedy(xy, r, want, veh_xy, veh_r, gap=self.static_gap)
        m = len(k)
        sc.static_valid[:m] = True
        sc.static_xy[:m] = xy[k]
        sc.static_heading[:m] = cand.heading[keep][k]
        sc.static_length[:m] = length[keep][k]
        sc.static_width[:m] = width[keep][k]


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
