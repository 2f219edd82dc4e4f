"""Recording an episode: step a `VecEnv` with a policy and keep one world's state per step.

The renderer (`render/episode.py`) draws from these snapshots, not from the live env, so an
episode can be recorded once and drawn many times (other cameras, sizes, formats). A snapshot
holds copies of one world's slices of the env's buffers (docs/world.md), about 10 kB for the
paper's slot counts (32 agents x 8 waypoints, 48 static vehicles, 8 pedestrians).

The world's spawn region (paper section 2.2: a 200 x 200 m square) and which agents started
parked live in the `Scenario`, not in the buffers; `ScenarioLog` wraps the env's spawner to
keep the scenario behind the recorded world's current episode.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from selfplaydrive.maps.roadmap import RoadMap
from selfplaydrive.rewards.registry import EVENT_NAMES

__all__ = ["Recording", "ScenarioLog", "WorldFrame", "record_episode", "snapshot"]


@dataclass
class WorldFrame:
    """One world's state after a step (A agent, S static, P pedestrian slots, K waypoints,
    G signal groups). Positions [m] in the map's local frame, headings [rad] from +x.

    Attributes:
        index: Frame number in the recording (0: the state after reset).
        time: Episode time [s] (world step counter times dt).
        episode: Episodes of this world started since the recording began (0, 1 ...).
        map_id: Index into `Recording.maps`.
        region: (4,) xmin, ymin, xmax, ymax [m] of the world's spawn region, or None when the
            scenario is unknown (an env whose spawner was not wrapped).
        agent_xy: (A, 2) box centres. agent_heading, agent_length, agent_width, agent_speed:
            (A,) [rad], [m], [m], [m/s].
        agent_valid: (A,) slot held an agent this episode. agent_active: (A,) still driving.
        agent_obstacle: (A,) ended and kept as a standing obstacle.
        agent_parked: (A,) started parked at the roadside (all False when unknown).
        agent_events: (A,) uint8 event bits of the last step (`_sim/common.pxd`): 1 vehicle
            collision, 2 pedestrian collision, 4 road-edge contact, 8 red light, 16 waypoint
            reached, 32 comfort.
        waypoints: (A, K, 2). num_wp, wp_idx: (A,) valid waypoints and the current one.
        static_xy (S, 2), static_cos, static_sin, static_length, static_width, static_valid (S,).
        ped_xy (P, 2), ped_cos, ped_sin, ped_length, ped_width (P,); ped_present (P,): valid
            and on the map (a pedestrian that vanished at the end of its path is not).
        light_state: (G,) int8 per signal group: 0 off, 1 red, 2 yellow, 3 green.
        events: (8,) int64 agent-step counts of this episode so far, order `EVENT_NAMES`.
    """

    index: int
    time: float
    episode: int
    map_id: int
    region: np.ndarray | None
    agent_xy: np.ndarray
    agent_heading: np.ndarray
    agent_length: np.ndarray
    agent_width: np.ndarray
    agent_speed: np.ndarray
    agent_valid: np.ndarray
    agent_active: np.ndarray
    agent_obstacle: np.ndarray
    agent_parked: np.ndarray
    agent_events: np.ndarray
    waypoints: np.ndarray
    num_wp: np.ndarray
    wp_idx: np.ndarray
    static_xy: np.ndarray
    static_cos: np.ndarray
    static_sin: np.ndarray
    static_length: np.ndarray
    static_width: np.ndarray
    static_valid: np.ndarray
    ped_xy: np.ndarray
    ped_cos: np.ndarray
    ped_sin: np.ndarray
    ped_length: np.ndarray
    ped_width: np.ndarray
    ped_present: np.ndarray
    light_state: np.ndarray
    events: np.ndarray


@dataclass
class Recording:
    """Frames of one world plus what drawing them needs.

    Attributes:
        maps: The env's maps (`WorldFrame.map_id` indexes them).
        world: The recorded world's index in the env.
        dt: Step length [s].
        frames: One `WorldFrame` per recorded state, in order.
        event_names: Names of `WorldFrame.events`.
    """

    maps: list[RoadMap]
    world: int
    dt: float
    frames: list[WorldFrame] = field(default_factory=list)
    event_names: tuple[str, ...] = EVENT_NAMES


class ScenarioLog:
    """Spawner wrapper that remembers the scenarios it hands out (same `sample` signature).

    `VecEnv` samples scenarios in world order at `reset` and for each autoreset world in
    `step`; which one went to a given world is found by comparing agent positions with the
    buffers (`scenario_of`), so the log does not depend on the env's sampling order.

    Args:
        inner: The spawner to wrap (`sample(road_map, rng, map_index) -> Scenario`).
    """

    def __init__(self, inner: object) -> None:
        self.inner = inner
        self.pending: list[object] = []

    def sample(self, road_map: RoadMap, rng: np.random.Generator, map_index: int = 0):
        sc = self.inner.sample(road_map, rng, map_index=map_index)
        self.pending.append(sc)
        return sc

    def __getattr__(self, name: str):  # state_dict, load_state_dict ... of the wrapped spawner
        if name == "inner":  # not set yet (copy, unpickling): no recursion
            raise AttributeError(name)
        return getattr(self.inner, name)

    def scenario_of(self, env, world: int):
        """The pending scenario packed into `world` (None if none matches); clears the log."""
        A = env.agents_per_world
        sl = slice(world * A, (world + 1) * A)
        xy = np.stack([env.state.x[sl], env.state.y[sl]], axis=1)
        valid = env.state.agent_valid[sl].astype(bool)
        found = None
        for sc in self.pending:
            if int(sc.map_index) != int(env.state.map_id[world]):
                continue
            if np.array_equal(np.asarray(sc.agent_valid, bool), valid) and np.allclose(
                np.asarray(sc.agent_xy, np.float32)[valid], xy[valid], atol=1e-4
            ):
                found = sc
        self.pending.clear()
        return found


def attach_log(env) -> ScenarioLog:
    """Wrap `env.spawner` in a `ScenarioLog` (once); returns the log."""
    if not isinstance(env.spawner, ScenarioLog):
        env.spawner = ScenarioLog(env.spawner)
    return env.spawner


def snapshot(env, world: int, scenario=None, index: int = 0, episode: int = 0) -> WorldFrame:
    """Copy world `world`'s state out of `env` (a `VecEnv`).

    Args:
        env: The env.
        world: World index.
        scenario: The `Scenario` of the world's current episode (region, parked flags), or None.
        index: Frame number to store.
        episode: Episode counter to store.
    """
    s, A = env.state, env.agents_per_world
    S, P, G = env.dims.S, env.dims.P, env.dims.G
    a, st, p = (
        slice(world * A, (world + 1) * A),
        slice(world * S, (world + 1) * S),
        slice(world * P, (world + 1) * P),
    )
    parked = np.zeros(A, dtype=bool)
    region = None
    if scenario is not None:
        parked = np.asarray(scenario.agent_parked, dtype=bool).copy()
        region = np.asarray(scenario.region, dtype=np.float64).copy()
    return WorldFrame(
        index=index,
        time=float(s.step[world]) * float(env.params.dt),
        episode=episode,
        map_id=int(s.map_id[world]),
        region=region,
        agent_xy=np.stack([s.x[a], s.y[a]], axis=1).astype(np.float64),
        agent_heading=s.heading[a].astype(np.float64),
        agent_length=s.length[a].copy(),
        agent_width=s.width[a].copy(),
        agent_speed=s.speed[a].copy(),
        agent_valid=s.agent_valid[a].astype(bool),
        agent_active=s.active[a].astype(bool),
        agent_obstacle=s.obstacle[a].astype(bool),
        agent_parked=parked,
        agent_events=s.events[a].copy(),
        waypoints=s.waypoints[a].copy(),
        num_wp=s.num_wp[a].copy(),
        wp_idx=s.wp_idx[a].copy(),
        static_xy=np.stack([s.st_x[st], s.st_y[st]], axis=1).astype(np.float64),
        static_cos=s.st_cos[st].copy(),
        static_sin=s.st_sin[st].copy(),
        static_length=s.st_len[st].copy(),
        static_width=s.st_wid[st].copy(),
        static_valid=s.st_valid[st].astype(bool),
        ped_xy=np.stack([s.ped_x[p], s.ped_y[p]], axis=1).astype(np.float64),
        ped_cos=s.ped_cos[p].copy(),
        ped_sin=s.ped_sin[p].copy(),
        ped_length=s.ped_len[p].copy(),
        ped_width=s.ped_wid[p].copy(),
        ped_present=(s.ped_valid[p] & s.ped_here[p]).astype(bool),
        light_state=s.light_state[world * G : (world + 1) * G].copy(),
        events=s.ev_count[world].copy(),
    )


def record_episode(
    env,
    policy: Callable[[np.ndarray, object], np.ndarray],
    steps: int,
    world: int = 0,
    seed: int = 0,
    on_frame: Callable[[WorldFrame], None] | None = None,
) -> Recording:
    """Reset `env`, step it `steps` times with `policy` and record world `world`.

    Every world is stepped (the env steps all at once); only `world` is recorded. When the
    world's episode ends inside the recording it autoresets (docs/world.md) and recording goes
    on with the next episode (`WorldFrame.episode` counts them).

    Args:
        env: A `VecEnv`. Its spawner is wrapped in a `ScenarioLog` (kept afterwards).
        policy: `policy(observations, env) -> (N, 2)` actions (`selfplaydrive/policies.py`); an
            optional `reset()` method is called after the env's reset.
        steps: Env steps to take (>= 0); the recording has `steps + 1` frames.
        world: The world to record, in [0, env.num_worlds).
        seed: Seed of `env.reset`.
        on_frame: Called with each new frame (e.g. to render while recording).

    Returns:
        The `Recording`.

    Raises:
        ValueError: `steps` negative or `world` out of range.
    """
    if int(steps) != steps or steps < 0:
        raise ValueError(f"steps: expected an integer >= 0, got {steps!r}")
    if int(world) != world or not 0 <= world < env.num_worlds:
        raise ValueError(
            f"world: expected an integer in [0, {env.num_worlds}) (the env's worlds), got {world!r}"
        )
    log = attach_log(env)
    log.pending.clear()
    env.reset(seed=seed)
    if hasattr(policy, "reset"):
        policy.reset()
    scenario, episode = log.scenario_of(env, world), 0
    rec = Recording(maps=list(env.maps), world=int(world), dt=float(env.params.dt))

    def keep(index: int) -> None:
        frame = snapshot(env, world, scenario, index=index, episode=episode)
        rec.frames.append(frame)
        if on_frame is not None:
            on_frame(frame)

    keep(0)
    for i in range(1, int(steps) + 1):
        env.step(policy(env.observations, env))
        if int(env.state.step[world]) == 0:  # autoreset: a new episode started in this world
            scenario, episode = log.scenario_of(env, world), episode + 1
        else:
            log.pending.clear()
        keep(i)
    return rec
