"""Long-form self-play evaluation: km between incidents (Gigaflow's protocol, paper section 5).

Protocol (reference/metrics.md section 2.4):

- every vehicle of every world is driven by the policy under evaluation, with the fixed
  evaluation coefficients of paper section 5 (`ConditioningSampler(mode="eval")`: every penalty
  at its training maximum, lane-centre bias B = 0, waypoint radius D = 3 m);
- long episodes (600 s by default); the env's episode limit is set just beyond `duration_s`
  so no world is reset by time inside the run; a world whose agents have all ended is
  resampled (autoreset) and its new agents count afresh;
- an agent that reaches its last waypoint gets a new route from where it is: `WaypointRefresher`
  localises it on the nearest lane of matching direction, walks a random legal route from there
  (`maps.routing.sample_routes`, the spawner's rule) and gives it up to K new waypoints
  (`VecEnv.set_waypoints`);
- incidents are onsets (rising edges) of the per-step event bits of agents that acted:
  vehicle collision, pedestrian collision, road-edge contact; red-light onsets are counted
  apart. Distance is the simulator's own odometer (`state.dist`, all agents). Intervals: Garwood
  for rates, inverted Garwood for km between incidents (docs/metrics.md section 2).

New routes go through `VecEnv.set_waypoints` (the refreshed agents' waypoints and counts, the
current waypoint back to the first). The kernels read them at the next step; the observation of
the step in which the last waypoint was reached still shows the old (exhausted) waypoints, a
one-step lag.

Example:
    >>> from selfplaydrive.eval.longform import RuleBasedPolicy, run_longform
    >>> res = run_longform("default", RuleBasedPolicy(), duration_s=1.0, num_worlds=1)
    >>> res.steps
    10
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from selfplaydrive.eval.stats import km_between_incidents, rate_per_km
from selfplaydrive.maps.roadmap import RoadMap
from selfplaydrive.scenario.types import COEFF_NAMES

__all__ = [
    "INCIDENT_TYPES",
    "LongformResult",
    "RuleBasedPolicy",
    "WaypointRefresher",
    "build_eval_env",
    "run_longform",
]

# Event bits (selfplaydrive/_sim/common.pxd EV_*) and the matching `ev_count` columns
# (sim.vec_env.EVENT_NAMES order).
EVENT_TYPES = {
    "vehicle_collisions": (1, "collision"),
    "pedestrian_collisions": (2, "pedestrian_collision"),
    "road_edge": (4, "offroad"),
    "red_light": (8, "red_light"),
}
INCIDENT_TYPES = ("vehicle_collisions", "pedestrian_collisions", "road_edge")  # Gigaflow's incident

Policy = Callable[[np.ndarray, Any], np.ndarray]


class RuleBasedPolicy:
    """`policy(obs, env) -> actions` around `RuleBasedDriver` (built on first use per env).

    Args:
        params: `DriverParams` (default constants when None).
    """

    def __init__(self, params: Any = None) -> None:
        self.params = params
        self._env: Any = None
        self._driver: Any = None

    def __call__(self, obs: np.ndarray, env: Any) -> np.ndarray:
        if self._driver is None or self._env is not env:
            from selfplaydrive.drivers.rule_based import RuleBasedDriver

            self._env, self._driver = env, RuleBasedDriver(env, self.params)
        return self._driver.act()


class WaypointRefresher:
    """Give agents that reached their last waypoint a new route and waypoints (section 2.2 rule).

    Args:
        env: The `VecEnv`.
        rng: Generator of the new routes.
        spacing_s: Mean time between waypoints at the speed limit [s] (the spawner's 5 s).
        jitter: Gaps are spacing_s * U(1 - jitter, 1 + jitter).
        lane_change_prob: Probability of a legal lane change per route step.
        search_radius: Lanes farther than this from the agent's centre are not candidates [m].
    """

    def __init__(
        self,
        env: Any,
        rng: np.random.Generator,
        spacing_s: float = 5.0,
        jitter: float = 0.5,
        lane_change_prob: float = 0.1,
        search_radius: float = 6.0,
    ) -> None:
        from selfplaydrive.drivers._lanes import LaneTable

        self.env, self.rng = env, rng
        self.spacing_s, self.jitter = float(spacing_s), float(jitter)
        self.lane_change_prob, self.search_radius = float(lane_change_prob), float(search_radius)
        self.lanes = LaneTable.build(env.maps)
        self.refreshed = 0  # agents given new waypoints
        self.unplaced = 0  # attempts where no lane of matching direction was near

    def due(self) -> np.ndarray:
        """Indices of active agents whose waypoints are used up (wp_idx >= num_wp > 0)."""
        st = self.env.state
        return np.flatnonzero(st.active.astype(bool) & (st.num_wp > 0) & (st.wp_idx >= st.num_wp))

    def localise(self, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(global lane, arc length s [m], found) of agents `idx`: the nearest centerline sample
        scored by lateral distance plus a heading penalty; lanes pointing away are excluded."""
        from selfplaydrive.drivers._lanes import MAP_SHIFT

        st, T = self.env.state, self.lanes
        A = self.env.agents_per_world
        m = st.map_id[idx // A].astype(np.float64)
        x, y = st.x[idx].astype(np.float64), st.y[idx].astype(np.float64)
        c, s = np.cos(st.heading[idx]), np.sin(st.heading[idx])
        k = min(16, len(T.sample_lane))
        dist, j = T.tree.query(np.c_[x + m * MAP_SHIFT, y], k=k, distance_upper_bound=self.search_radius)
        dist, j = dist.reshape(len(idx), k), j.reshape(len(idx), k)
        ok = np.isfinite(dist)
        j = np.where(ok, j, 0)
        lane, s_arc = T.sample_lane[j], T.sample_s[j]
        pxy, tan = T.point_at(lane, s_arc)
        rel = np.stack([x, y], 1)[:, None, :] - pxy
        s_arc = np.clip(s_arc + (rel * tan).sum(-1), 0.0, T.length[lane])
        pxy, tan = T.point_at(lane, s_arc)
        rel = np.stack([x, y], 1)[:, None, :] - pxy
        lat = np.abs(rel[..., 0] * tan[..., 1] - rel[..., 1] * tan[..., 0])
        cosd = tan[..., 0] * c[:, None] + tan[..., 1] * s[:, None]
        cost = np.where(ok & (cosd > 0.5), lat + 4.0 * (1.0 - cosd), np.inf)  # within 60 deg
        best = cost.argmin(axis=1)
        r = np.arange(len(idx))
        return lane[r, best], s_arc[r, best], np.isfinite(cost[r, best])

    def refresh(self) -> int:
        """Write new waypoints for every due agent; returns how many were refreshed."""
        from selfplaydrive.maps.routing import batch_waypoints, route_tables, sample_routes, waypoint_times

        idx = self.due()
        if len(idx) == 0:
            return 0
        lane, s, found = self.localise(idx)
        self.unplaced += int((~found).sum())
        idx, lane, s = idx[found], lane[found], s[found]
        T, K = self.lanes, self.env.dims.K
        for m in np.unique(T.lane_map[lane]):
            sel = T.lane_map[lane] == m
            rows, local = idx[sel], lane[sel] - T.lane_base[m]
            tables = route_tables(self.env.maps[int(m)])
            times = waypoint_times(self.rng, len(rows), K, self.spacing_s, self.jitter)
            routes = sample_routes(tables, local, s[sel], times[:, -1], self.rng, self.lane_change_prob)
            wps, count = batch_waypoints(tables, routes, times)
            self.env.set_waypoints(rows, wps, count)
        self.refreshed += len(idx)
        return len(idx)


@dataclass
class LongformResult:
    """Counts of a long-form run and their estimates (`to_dict`).

    Attributes:
        duration_s: Simulated time per world [s].
        num_worlds: Worlds stepped together.
        seed: Reset seed.
        steps: Env steps taken.
        dt: Step length [s].
        km: Distance driven by all agents [km].
        agent_hours: Agent-steps in which an agent acted, times dt [h].
        onsets: Incidents per type (edge-triggered onsets).
        agent_steps: Agent-steps with the event bit set, per type.
        world_episodes: World episodes that ended inside the run (all agents ended).
        waypoint_refreshes: Agents given new waypoints.
        coefficients: The evaluation coefficient vector, by name.
    """

    duration_s: float
    num_worlds: int
    seed: int
    steps: int
    dt: float
    km: float
    agent_hours: float
    onsets: dict[str, int]
    agent_steps: dict[str, int]
    world_episodes: int
    waypoint_refreshes: int
    coefficients: dict[str, float] = field(default_factory=dict)

    @property
    def incidents(self) -> int:
        """Vehicle + pedestrian collision + road-edge onsets (Gigaflow's incident)."""
        return sum(self.onsets[t] for t in INCIDENT_TYPES)

    def to_dict(self) -> dict[str, Any]:
        """Protocol, totals and estimates (JSON-safe: estimates as their dicts)."""
        k_all = self.incidents
        out: dict[str, Any] = {
            "protocol": {
                "duration_s": self.duration_s,
                "num_worlds": self.num_worlds,
                "seed": self.seed,
                "steps": self.steps,
                "dt": self.dt,
                "coefficients": self.coefficients,
            },
            "km": self.km,
            "agent_hours": self.agent_hours,
            "mean_speed_kmh": self.km / self.agent_hours if self.agent_hours > 0 else float("nan"),
            "incidents": k_all,
            "onsets": dict(self.onsets),
            "agent_steps": dict(self.agent_steps),
            "world_episodes": self.world_episodes,
            "waypoint_refreshes": self.waypoint_refreshes,
            "km_between_incidents": km_between_incidents(k_all, self.km).to_dict(),
            "km_between_incidents_incl_red": km_between_incidents(
                k_all + self.onsets["red_light"], self.km
            ).to_dict(),
            "hours_between_incidents": self.agent_hours / k_all if k_all else float("inf"),
        }
        for t in EVENT_TYPES:
            out[f"km_between_{t}"] = km_between_incidents(self.onsets[t], self.km).to_dict()
            out[f"{t}_per_km"] = rate_per_km(self.onsets[t], self.km).to_dict()
        return out


class _OnsetCounter:
    """Edge-triggered event counts of the agents that acted, plus per-world agent-step totals
    to recover the final step of a world that autoreset (its event bits are cleared by then)."""

    def __init__(self, env: Any) -> None:
        self.env = env
        self.prev = {t: np.zeros(env.num_agents, dtype=bool) for t in EVENT_TYPES}
        self.onsets = dict.fromkeys(EVENT_TYPES, 0)
        self.agent_steps = dict.fromkeys(EVENT_TYPES, 0)
        self.episode_steps = {t: np.zeros(env.num_worlds, dtype=np.int64) for t in EVENT_TYPES}
        self.acted_steps = 0

    def after_step(self) -> None:
        env = self.env
        acted = env.reward_mask
        self.acted_steps += int(acted.sum())
        ev = env.state.events
        A = env.agents_per_world
        for t, (bit, _) in EVENT_TYPES.items():
            flag = ((ev & bit) != 0) & acted
            self.onsets[t] += int(np.count_nonzero(flag & ~self.prev[t]))
            n = int(np.count_nonzero(flag))
            self.agent_steps[t] += n
            if n:
                self.episode_steps[t] += flag.reshape(-1, A).sum(axis=1)
            self.prev[t] = flag

    def episode_ended(self, rec: dict[str, Any]) -> None:
        """Add the events of the world's last step (wiped by the autoreset) from its statistics.

        Every such agent-step is counted as an onset: with the evaluation coefficients collisions
        and road-edge contacts end the agent at their first step, so this is exact for them.
        """
        w = int(rec["world"])
        for t, (_, name) in EVENT_TYPES.items():
            missing = int(rec["events"][name]) - int(self.episode_steps[t][w])
            if missing > 0:
                self.onsets[t] += missing
                self.agent_steps[t] += missing
            self.episode_steps[t][w] = 0
        A = self.env.agents_per_world
        for t in EVENT_TYPES:
            self.prev[t][w * A : (w + 1) * A] = False


class _Progress:
    """One status line per tenth of a run (long runs are otherwise silent for minutes)."""

    def __init__(self, say: Callable[[str], None] | None, steps: int, dt: float) -> None:
        self.say, self.steps, self.dt = say, steps, dt
        self.every = max(1, steps // 10)
        self.start = time.perf_counter()

    def due(self, done: int) -> bool:
        """Whether a line is due after `done` steps."""
        return self.say is not None and (done % self.every == 0 or done == self.steps)

    def say_status(self, done: int, km: float, onsets: dict[str, int]) -> None:
        """Report `done` steps, `km` driven so far and the onsets by type."""
        incidents = sum(onsets[t] for t in INCIDENT_TYPES)
        self.say(
            f"longform: {done * self.dt:.1f}/{self.steps * self.dt:.1f} s simulated, {km:.2f} km, "
            f"{incidents} incidents ({time.perf_counter() - self.start:.0f} s)"
        )


def _eval_spawner(duration_s: float, spawner_kwargs: dict[str, Any]) -> Any:
    from selfplaydrive.scenario.conditioning import ConditioningSampler
    from selfplaydrive.scenario.spawner import PaperSpawner

    kw = {"conditioning": ConditioningSampler(mode="eval")}
    kw.update(spawner_kwargs)
    # the limit lies past the run so no world is cut (and its last events wiped) by time
    return PaperSpawner(episode_lengths=(duration_s + 1.0,), **kw)


def build_eval_env(
    source: Any, spawner: Any, num_worlds: int, seed: int, env_kwargs: dict[str, Any] | None = None
) -> Any:
    """A `VecEnv` with `spawner` from maps or an env factory (see `run_longform`).

    Raises:
        ValueError: `source` is neither maps nor a callable.
    """
    env_kwargs = dict(env_kwargs or {})
    if isinstance(source, (RoadMap, str)) or (isinstance(source, Sequence) and not callable(source)):
        from selfplaydrive.builder import make_env

        return make_env(source, spawner=spawner, num_worlds=num_worlds, seed=seed, **env_kwargs)
    if callable(source):
        return source(spawner=spawner, num_worlds=num_worlds, seed=seed, **env_kwargs)
    raise ValueError(
        f"run_longform: expected maps (a RoadMap, a load_map spec or a list) or an env factory "
        f"callable(spawner=, num_worlds=, seed=), got {type(source).__name__}"
    )


def run_longform(
    env_factory_or_maps: Any,
    policy: Policy,
    duration_s: float = 600.0,
    num_worlds: int = 4,
    seed: int = 0,
    spawner_kwargs: dict[str, Any] | None = None,
    env_kwargs: dict[str, Any] | None = None,
    refresh_waypoints: bool = True,
    progress: Callable[[str], None] | None = None,
) -> LongformResult:
    """Run the long-form protocol (module docstring) and count incidents and distance.

    Args:
        env_factory_or_maps: Maps for `make_env` (a `RoadMap`, a spec such as "default", or a
            list), or a factory `f(spawner=, num_worlds=, seed=, **env_kwargs) -> VecEnv` that
            must use the spawner it is given (it carries the evaluation coefficients).
        policy: `policy(obs, env) -> (N, 2) actions` (e.g. `RuleBasedPolicy()`).
        duration_s: Simulated time per world [s] (600 by default).
        num_worlds: Worlds stepped together.
        seed: Reset seed (worlds, spawns and new routes).
        spawner_kwargs: Extra `PaperSpawner` arguments (e.g. num_agents).
        env_kwargs: Extra `VecEnv` arguments (num_threads, terminated_vehicle ...).
        refresh_waypoints: Give agents new waypoints when their route ends.
        progress: Called with a one-line status (simulated time, km, incidents, wall time)
            after every tenth of the run; None is silent.

    Returns:
        The `LongformResult`.

    Raises:
        ValueError: On a non-positive duration or num_worlds, or actions the env rejects.
    """
    if not (np.isfinite(duration_s) and duration_s > 0):
        raise ValueError(f"duration_s: expected a positive number of seconds, got {duration_s!r}")
    if int(num_worlds) < 1:
        raise ValueError(f"num_worlds: expected an integer >= 1, got {num_worlds!r}")
    spawner = _eval_spawner(float(duration_s), dict(spawner_kwargs or {}))
    env = build_eval_env(env_factory_or_maps, spawner, int(num_worlds), int(seed), env_kwargs)
    dt = float(env.params.dt)
    steps = round(duration_s / dt)
    obs = env.reset(seed=seed)
    counter = _OnsetCounter(env)
    refresher = WaypointRefresher(env, np.random.default_rng([seed, 1])) if refresh_waypoints else None
    km_done, episodes = 0.0, 0
    report = _Progress(progress, steps, dt)
    for k in range(steps):
        env.step(policy(obs, env))
        obs = env.observations
        counter.after_step()
        for rec in env.pop_episode_stats():
            counter.episode_ended(rec)
            km_done += float(rec["km"])
            episodes += 1
        if refresher is not None:
            refresher.refresh()
        if report.due(k + 1):
            report.say_status(k + 1, km_done + float(np.sum(env.state.dist)) / 1000.0, counter.onsets)
    km = km_done + float(np.sum(env.state.dist)) / 1000.0
    coeffs = spawner.conditioning.eval_vector() if spawner.conditioning.mode == "eval" else None
    return LongformResult(
        duration_s=float(duration_s),
        num_worlds=int(num_worlds),
        seed=int(seed),
        steps=steps,
        dt=dt,
        km=km,
        agent_hours=counter.acted_steps * dt / 3600.0,
        onsets=dict(counter.onsets),
        agent_steps=dict(counter.agent_steps),
        world_episodes=episodes,
        waypoint_refreshes=refresher.refreshed if refresher is not None else 0,
        coefficients={} if coeffs is None else dict(zip(COEFF_NAMES, map(float, coeffs), strict=True)),
    )
