"""Rule-adherence suites (paper section 5.3): the protocol, the fixed-scenario spawner and the
runner that records trajectories.

A suite builds hand-placed `Scenario`s on a map (`generate`), a policy drives them in a
`VecEnv`, and a pure classifier turns each recorded `Trajectory` into an outcome
(`classify`); `summarise` aggregates outcomes into proportions with Wilson 95 % intervals.

Every suite scenario uses the same slot layout (`AGENT_SLOTS` agents, `STATIC_SLOTS` static
vehicles, `PED_SLOTS` pedestrians, `WAYPOINT_SLOTS` waypoints), so any suite runs in any env
built for another one. Unused slots are invalid; traffic lights are off; every agent gets the
evaluation coefficients of paper section 5 (`ConditioningSampler(mode="eval")`) and nominal
hidden dynamics (friction 1.0, gains 1.0), so outcomes differ only by placement.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from selfplaydrive.maps.roadmap import RoadMap, SegmentType
from selfplaydrive.obs.layout import ObsLayout
from selfplaydrive.scenario.conditioning import ConditioningSampler
from selfplaydrive.scenario.pedestrians import PATH_POINTS
from selfplaydrive.scenario.types import Scenario

AGENT_SLOTS = 2  # A: the ego, and the second vehicle of the stop-line suite
STATIC_SLOTS = 1  # S: always invalid (the kernels want at least one slot of each kind)
PED_SLOTS = 1  # P: the pedestrian of the crosswalk suite
WAYPOINT_SLOTS = 4  # K
NOMINAL_HIDDEN = (1.0, 1.0, 1.0)  # friction mu, acceleration gain, steering gain
REGION_SIZE = 200.0  # [m] edge of the square `Scenario.region` around the scene


@dataclass
class SuiteScenario:
    """One prepared scenario of a suite and what its classifier needs.

    Attributes:
        suite: Suite name ("turn_lanes", "stop_lines", "crosswalks").
        scenario: The initial state packed into the env.
        paths: Named reference polylines, (n, 2) float64 [m] (e.g. the correct approach
            corridor, each vehicle's route); the classifiers project trajectories onto them.
        info: JSON-ready facts: map, lanes, distances [m], speeds [m/s], times [s], variant.
    """

    suite: str
    scenario: Scenario
    paths: dict[str, np.ndarray] = field(default_factory=dict)
    info: dict[str, Any] = field(default_factory=dict)


@dataclass
class Trajectory:
    """What happened in one suite episode, step by step (frame 0 is the initial state).

    Attributes:
        dt: Step length [s].
        xy: (F, A, 2) float32 box centres [m].
        heading: (F, A) float32 [rad].
        speed: (F, A) float32 [m/s].
        active: (F, A) bool, the agent was still driving.
        ped_xy: (F, P, 2) float32 pedestrian centres [m].
        collided: (A,) bool, the agent collided with a vehicle or pedestrian (collision term).
        collision_frame: (A,) int32 first frame after the collision, -1 without one.
        offroad: (A,) bool, the agent touched a road edge.
        red_light: (A,) bool, the simulator's red-light term fired for the agent (the reward's
            view; the red-light suite classifies geometrically instead, section 5.1), or None
            for a trajectory made by hand.
    """

    dt: float
    xy: np.ndarray
    heading: np.ndarray
    speed: np.ndarray
    active: np.ndarray
    ped_xy: np.ndarray
    collided: np.ndarray
    collision_frame: np.ndarray
    offroad: np.ndarray
    red_light: np.ndarray | None = None

    @property
    def time(self) -> np.ndarray:
        """(F,) time of each frame [s]."""
        return np.arange(len(self.xy)) * self.dt


class Suite(Protocol):
    """A rule-adherence suite: scenario generator plus pure classifier."""

    name: str

    def generate(
        self, road_map: RoadMap, rng: np.random.Generator, count: int, map_index: int = 0
    ) -> list[SuiteScenario]:
        """Up to `count` scenarios on `road_map` (fewer, with a `UserWarning`, when the map lacks
        places)."""

    def classify(self, item: SuiteScenario, traj: Trajectory) -> dict[str, Any]:
        """Outcome of one episode: a JSON-ready dict with at least the key "outcome"."""

    def summarise(self, outcomes: Sequence[dict[str, Any]]) -> dict[str, Any]:
        """Aggregate outcomes (proportions with Wilson 95 % intervals)."""


def eval_coefficients() -> np.ndarray:
    """(len(COEFF_NAMES),) float32: the evaluation coefficients of paper section 5."""
    return ConditioningSampler(mode="eval").eval_vector()


def blank_scenario(road_map: RoadMap, map_index: int, centre: np.ndarray, episode_length: float) -> Scenario:
    """A scenario with every slot invalid, lights off and a `REGION_SIZE` region around `centre`."""
    h = REGION_SIZE / 2
    region = np.array([centre[0] - h, centre[1] - h, centre[0] + h, centre[1] + h])
    return Scenario.empty(
        AGENT_SLOTS,
        WAYPOINT_SLOTS,
        STATIC_SLOTS,
        PED_SLOTS,
        PATH_POINTS,
        road_map.num_signal_groups,
        map_index,
        region,
        episode_length,
    )


def put_agent(
    sc: Scenario,
    slot: int,
    xy: np.ndarray,
    heading: float,
    speed: float,
    size: tuple[float, float],
    lane: int,
    waypoints: np.ndarray,
) -> None:
    """Fill agent `slot` of `sc` (evaluation coefficients, nominal hidden parameters).

    Args:
        xy: (2,) box centre [m]; heading [rad]; speed [m/s]; size (length, width) [m].
        lane: Lane the agent starts on.
        waypoints: (k, 2) route waypoints [m], k <= `WAYPOINT_SLOTS`.
    """
    k = len(waypoints)
    if not 1 <= k <= WAYPOINT_SLOTS:
        raise ValueError(f"waypoints: expected 1..{WAYPOINT_SLOTS} points, got {k}")
    sc.agent_valid[slot] = True
    sc.agent_xy[slot] = xy
    sc.agent_heading[slot] = heading
    sc.agent_speed[slot] = speed
    sc.agent_length[slot], sc.agent_width[slot] = size
    sc.agent_lane[slot] = lane
    sc.waypoints[slot, :k] = waypoints
    sc.waypoints[slot, k:] = waypoints[-1]
    sc.num_waypoints[slot] = k
    sc.coeffs[slot] = eval_coefficients()
    sc.hidden[slot] = NOMINAL_HIDDEN


def warn_shortfall(suite: str, road_map: RoadMap, got: int, want: int, why: str) -> None:
    """Warn that a map offered fewer places than requested."""
    if got < want:
        warnings.warn(
            f"{suite}: map {road_map.name!r} yields {got} of count={want} scenarios ({why})",
            UserWarning,
            stacklevel=3,
        )


class FixedScenarioSpawner:
    """Spawner returning prepared scenarios one after another (a `VecEnv` spawner).

    `VecEnv` samples world 0, 1, ... in order at `reset(seed)`, so after `set_batch(batch)` and
    a reset, world w holds `batch[w]`. Calls past the end of the batch (autoresets of finished
    worlds, surplus worlds) repeat the batch's first scenario; `run_suite` ignores those.

    Args:
        scenarios: The first batch (at least one scenario).
    """

    def __init__(self, scenarios: Sequence[Scenario]) -> None:
        self.set_batch(scenarios)

    def set_batch(self, scenarios: Sequence[Scenario]) -> None:
        """Serve `scenarios` from the next call on."""
        if len(scenarios) == 0:
            raise ValueError("FixedScenarioSpawner: expected at least one scenario, got none")
        self.batch = list(scenarios)
        self.calls = 0

    def sample(self, road_map: RoadMap, rng: np.random.Generator, map_index: int = 0) -> Scenario:
        i = self.calls
        self.calls += 1
        return self.batch[i] if i < len(self.batch) else self.batch[0]


def hide_stop_lines(obs: np.ndarray, layout: ObsLayout) -> np.ndarray:
    """Copy of `obs` with every STOP_LINE road row set to padding (all zeros, valid 0).

    The kernel writes the road type as `SegmentType / 4` (obs/layout.py), so stop-line rows
    carry 0.5 in the type column. Rows are blanked in place, not compacted: a model must
    treat padding wherever it appears (the valid column), which every model here does.
    """
    out = np.array(obs, dtype=np.float32, copy=True)
    road = layout.split(out)["road"]
    t = road[:, :, layout.feature_index("road", "type")]
    v = road[:, :, layout.feature_index("road", "valid")]
    mask = (v > 0.5) & np.isclose(t, SegmentType.STOP_LINE / 4.0, atol=1e-3)
    road[mask] = 0.0
    return out


PolicyFactory = Callable[[Any], Callable[[np.ndarray], np.ndarray]]


def make_env(maps: RoadMap | Sequence[RoadMap], spawner: FixedScenarioSpawner, num_worlds: int, **kwargs):
    """Default env of `run_suite`: a `VecEnv` with the paper's defaults."""
    from selfplaydrive.sim.vec_env import VecEnv

    return VecEnv(maps, spawner, num_worlds, **kwargs)


def run_suite(
    env_factory_or_maps: RoadMap | Sequence[RoadMap] | Callable[..., Any],
    policy: PolicyFactory,
    scenarios: Sequence[SuiteScenario],
    batch_size: int = 32,
    hide_stop_lines_obs: bool = False,
    seed: int = 0,
) -> list[Trajectory]:
    """Drive every scenario once with `policy` and record its trajectory.

    Args:
        env_factory_or_maps: The env's maps (a `VecEnv` with default settings is built), or a
            callable `(spawner, num_worlds) -> VecEnv` for other settings.
        policy: Factory `policy(env) -> act`, `act(obs) -> actions` (e.g. `RuleBasedDriver`).
            `act.reset()` is called after every env reset when it exists, and
            `act.begin(batch)` with the batch's `SuiteScenario`s (world w holds batch[w]).
        scenarios: The suite's scenarios (their `map_index` refers to the env's maps).
        batch_size: Worlds stepped together.
        hide_stop_lines_obs: Blank STOP_LINE road rows before the policy sees an observation
            (`hide_stop_lines`), for the stop-line ablation of section 5.3.
        seed: Seed of the env resets (batch b uses seed + b).

    Returns:
        One `Trajectory` per scenario, in order.
    """
    if len(scenarios) == 0:
        return []
    if int(batch_size) < 1:
        raise ValueError(f"batch_size: expected an integer >= 1, got {batch_size!r}")
    W = min(int(batch_size), len(scenarios))
    spawner = FixedScenarioSpawner([s.scenario for s in scenarios[:W]])
    if callable(env_factory_or_maps) and not isinstance(env_factory_or_maps, RoadMap):
        env = env_factory_or_maps(spawner, W)
    else:
        env = make_env(env_factory_or_maps, spawner, W)
    act = policy(env)
    out: list[Trajectory] = []
    for b, start in enumerate(range(0, len(scenarios), W)):
        batch = list(scenarios[start : start + W])
        spawner.set_batch([s.scenario for s in batch])
        out.extend(_run_batch(env, act, batch, seed + b, hide_stop_lines_obs))
    return out


def _run_batch(env, act, batch: list[SuiteScenario], seed: int, hide: bool) -> list[Trajectory]:
    """Reset the env into `batch` and step until every world's first episode ended."""
    obs = env.reset(seed=seed)
    if hasattr(act, "reset"):
        act.reset()
    if hasattr(act, "begin"):
        act.begin(batch)
    n, A, P = len(batch), env.agents_per_world, env.dims.P
    dt = float(env.params.dt)
    steps = max(max(1, round(s.scenario.episode_length / dt)) for s in batch)
    rec = _Recorder(n, steps + 1, A, P)
    rec.frame(env.state, 0, np.ones(n, bool))
    running = np.ones(n, bool)
    col = list(env.term_names).index("collision")
    off = list(env.term_names).index("offroad")
    red = list(env.term_names).index("red_light")
    for f in range(1, steps + 1):
        o = hide_stop_lines(obs, env.layout) if hide else obs
        env.step(act(o))
        obs = env.observations
        acted = env.reward_mask.reshape(env.num_worlds, A)[:n]
        terms = env.reward_terms.reshape(env.num_worlds, A, -1)[:n]
        hit = running[:, None] & acted & (terms[..., col] != 0)
        rec.collision_frame[hit & (rec.collision_frame < 0)] = f
        rec.offroad |= running[:, None] & acted & (terms[..., off] != 0)
        rec.red_light |= running[:, None] & acted & (terms[..., red] != 0)
        running &= env.state.step[:n] != 0  # an autoreset world starts again at step 0
        rec.frame(env.state, f, running)
        if not running.any():
            break
    return [rec.trajectory(w, dt) for w in range(n)]


class _Recorder:
    """Per-world frame buffers of one batch; a world's frames stop when its episode ends."""

    def __init__(self, n: int, frames: int, A: int, P: int) -> None:
        self.n, self.A, self.P = n, A, P
        self.xy = np.zeros((n, frames, A, 2), np.float32)
        self.heading = np.zeros((n, frames, A), np.float32)
        self.speed = np.zeros((n, frames, A), np.float32)
        self.active = np.zeros((n, frames, A), bool)
        self.ped_xy = np.zeros((n, frames, P, 2), np.float32)
        self.frames = np.zeros(n, np.int64)
        self.collision_frame = np.full((n, A), -1, np.int32)
        self.offroad = np.zeros((n, A), bool)
        self.red_light = np.zeros((n, A), bool)

    def frame(self, st, f: int, which: np.ndarray) -> None:
        n, A, P = self.n, self.A, self.P
        w = np.flatnonzero(which)
        if len(w) == 0:
            return
        self.xy[w, f, :, 0] = st.x[: n * A].reshape(n, A)[w]
        self.xy[w, f, :, 1] = st.y[: n * A].reshape(n, A)[w]
        self.heading[w, f] = st.heading[: n * A].reshape(n, A)[w]
        self.speed[w, f] = st.speed[: n * A].reshape(n, A)[w]
        self.active[w, f] = st.active[: n * A].reshape(n, A)[w].astype(bool)
        self.ped_xy[w, f, :, 0] = st.ped_x[: n * P].reshape(n, P)[w]
        self.ped_xy[w, f, :, 1] = st.ped_y[: n * P].reshape(n, P)[w]
        self.frames[w] = f + 1

    def trajectory(self, w: int, dt: float) -> Trajectory:
        k = int(self.frames[w])
        return Trajectory(
            dt=dt,
            xy=self.xy[w, :k].copy(),
            heading=self.heading[w, :k].copy(),
            speed=self.speed[w, :k].copy(),
            active=self.active[w, :k].copy(),
            ped_xy=self.ped_xy[w, :k].copy(),
            collided=self.collision_frame[w] >= 0,
            collision_frame=self.collision_frame[w].copy(),
            offroad=self.offroad[w].copy(),
            red_light=self.red_light[w].copy(),
        )
