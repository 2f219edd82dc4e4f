"""Closed-loop evaluation on logged scenarios, Waymax-style (paper section 5.2, Table 2).

Per scenario (`run_logged`):

1. `build_scenario(log, start=10)`: the simulator's initial state from the log at t = 10 (the
   11th step, Waymax's `init_steps = 11`). Agent slot 0 is the ego (the SDC, or the first valid
   vehicle); the other vehicles and cyclists valid at t = 10 whose logged path over the rollout is
   at least `min_move` long are agents; those that barely move become static vehicles;
   pedestrians walk their logged path (polyline of their valid future positions, constant speed =
   path length / time). Every agent's waypoints are points of its own logged future path, evenly
   spaced in arc length (at most `max_waypoints`, the last one the final logged position), and
   its coefficients are the fixed evaluation vector (paper section 5). No traffic lights.
2. The rollout: T - 1 - start steps (80 for WOMD); the ego acts by `policy(obs, env)` (its slot's
   row), the others by the rule-based driver (`others="rule_based"`, the paper's IDM agents) or by
   log replay (`others="log"`: after every step their pose and speed are set to the log's,
   `VecEnv.set_poses`). Agents that end (collision, road edge with the evaluation coefficients)
   stay as obstacles.
3. Metrics (`waymax_episode`, docs/metrics.md section 3): the ego's boxes over all T steps (log
   history up to `start`, simulated after), its velocity (speed along the heading), collision
   against every other object (simulated agents, static vehicles, pedestrians, and log replay of
   objects absent at t = 10), off-road against the file's oriented road edges, kinematic
   infeasibility, log ADE/FDE and log route progress.

`evaluate_logged(paths, policy)` loops over files and returns the records and `aggregate_waymax`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from selfplaydrive.eval.logged.gpudrive_json import LoggedScenario, load_gpudrive_json
from selfplaydrive.eval.waymax_episode import WaymaxRecord, aggregate_waymax, waymax_episode
from selfplaydrive.eval.waymax_metrics import RoadEdges
from selfplaydrive.scenario.types import COEFF_NAMES, HIDDEN_PARAMS, Scenario

__all__ = ["LogSpawner", "SceneLayout", "build_scenario", "evaluate_logged", "run_logged"]

PED_POINTS = 16  # path points kept per pedestrian
SENTINEL_GAP = 500.0  # [m] beyond the map's upper corner, outside every observation radius


@dataclass(frozen=True)
class SceneLayout:
    """Which log object sits in which simulator slot.

    Attributes:
        agents: (A,) log indices of the agent slots; slot 0 is the ego (slot A is the sentinel).
        statics: (S,) log indices of static vehicles.
        peds: (P,) log indices of pedestrians.
        replay: Log indices of objects not simulated (absent at `start`), log-replayed for metrics.
    """

    agents: np.ndarray
    statics: np.ndarray
    peds: np.ndarray
    replay: np.ndarray


def _path_length(xy: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(xy, axis=0), axis=1).sum()) if len(xy) > 1 else 0.0


def _future(log: LoggedScenario, i: int, start: int) -> np.ndarray:
    """(n, 2) valid logged positions of object i from `start` on."""
    return log.xy[i, start:][log.valid[i, start:]]


def path_waypoints(path: np.ndarray, k_max: int, spacing: float = 10.0) -> tuple[np.ndarray, int]:
    """Up to `k_max` points evenly spaced in arc length along `path` (about `spacing` [m] apart,
    the last one the path's end), padded with the last; (k_max, 2) float32 and the count."""
    out = np.zeros((k_max, 2), dtype=np.float32)
    if len(path) == 0:
        return out, 0
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    n = int(min(k_max, max(1, np.ceil(cum[-1] / spacing))))
    s = cum[-1] * np.arange(1, n + 1) / n
    pts = np.c_[np.interp(s, cum, path[:, 0]), np.interp(s, cum, path[:, 1])]
    out[:n] = pts
    out[n:] = pts[-1]
    return out, n


def _layout(log: LoggedScenario, ego: int, start: int, min_move: float) -> SceneLayout:
    here = log.valid[:, start]
    movers, statics = [ego], []
    for i in np.flatnonzero(here & np.isin(log.kind, ("vehicle", "cyclist"))):
        if i == ego:
            continue
        (movers if _path_length(_future(log, int(i), start)) >= min_move else statics).append(int(i))
    peds = [int(i) for i in np.flatnonzero(here & (log.kind == "pedestrian"))]
    used = set(movers) | set(statics) | set(peds)
    replay = [i for i in range(len(log.kind)) if i not in used and log.valid[i].any()]
    return SceneLayout(*(np.array(v, dtype=np.int64) for v in (movers, statics, peds, replay)))


def build_scenario(
    log: LoggedScenario,
    start: int = 10,
    ego: int | None = None,
    max_waypoints: int = 8,
    min_move: float = 1.0,
    coeffs: np.ndarray | None = None,
) -> tuple[Scenario, SceneLayout]:
    """The simulator's initial state from the log at step `start` (module docstring, step 1).

    Args:
        log: The loaded scenario.
        start: Index of the initial step (10 = Waymax's current step).
        ego: Log index of the ego (default `log.ego_index(start)`).
        max_waypoints: K, waypoint slots per agent.
        min_move: Logged path length over the rollout [m] below which a vehicle is static.
        coeffs: (len(COEFF_NAMES),) coefficients of every agent (default: evaluation vector).

    Raises:
        ValueError: `start` outside [0, T - 2] or an ego that is not valid at `start`.
    """
    T = log.num_steps
    if not 0 <= start <= T - 2:
        raise ValueError(f"start={start}: expected 0 <= start <= T - 2 = {T - 2} (at least one rollout step)")
    ego = log.ego_index(start) if ego is None else int(ego)
    if not log.valid[ego, start]:
        raise ValueError(f"{log.path}: ego object {ego} is not valid at step {start}")
    if coeffs is None:
        from selfplaydrive.scenario.conditioning import ConditioningSampler

        coeffs = ConditioningSampler(mode="eval").eval_vector()
    lay = _layout(log, ego, start, min_move)
    a, t = lay.agents, start
    A, S, P = len(a) + 1, max(1, len(lay.statics)), max(1, len(lay.peds))
    f32 = np.float32
    wps = [path_waypoints(_future(log, int(i), start + 1), max_waypoints) for i in a]
    # the last slot is a sentinel parked SENTINEL_GAP beyond the map: it never ends, so the world
    # is never reset inside the rollout and the final poses of agents that ended stay readable
    far = np.asarray(log.road_map.bounds[2:], np.float64) + SENTINEL_GAP
    wps.append((np.tile(far, (max_waypoints, 1)).astype(f32), 1))
    xy = np.r_[log.xy[a, t], far[None]]
    heading = np.r_[log.heading[a, t], 0.0]
    speed = np.r_[np.linalg.norm(log.vel[a, t], axis=1), 0.0]
    size = np.r_[log.length[a], 4.0], np.r_[log.width[a], 1.8]
    sc = Scenario(
        map_index=0,
        region=np.asarray(log.road_map.bounds, f32),
        agent_valid=np.ones(A, bool),
        agent_xy=xy.astype(f32),
        agent_heading=heading.astype(f32),
        agent_speed=speed.astype(f32),
        agent_length=size[0].astype(f32),
        agent_width=size[1].astype(f32),
        agent_parked=np.zeros(A, bool),
        agent_lane=np.full(A, -1, np.int32),
        waypoints=np.stack([w for w, _ in wps]),
        num_waypoints=np.array([n for _, n in wps], np.int32),
        coeffs=np.tile(np.asarray(coeffs, f32), (A, 1)),
        hidden=np.ones((A, len(HIDDEN_PARAMS)), f32),  # nominal friction 1, gains 1
        **_statics(log, lay.statics, t, S),
        **_pedestrians(log, lay.peds, t, P),
        lights_enabled=False,
        light_state=np.zeros(log.road_map.num_signal_groups, np.int8),
        light_time_left=np.zeros(log.road_map.num_signal_groups, f32),
        # just past the rollout, so the env never resets the world inside it
        episode_length=(T - 1 - start) * log.dt + 1.0,
    )
    assert sc.coeffs.shape[1] == len(COEFF_NAMES)
    return sc, lay


def _statics(log: LoggedScenario, idx: np.ndarray, t: int, S: int) -> dict[str, np.ndarray]:
    f32, n = np.float32, len(idx)
    out = {
        "static_valid": np.zeros(S, bool),
        "static_xy": np.zeros((S, 2), f32),
        "static_heading": np.zeros(S, f32),
        "static_length": np.ones(S, f32),
        "static_width": np.ones(S, f32),
    }
    out["static_valid"][:n] = True
    out["static_xy"][:n] = log.xy[idx, t]
    out["static_heading"][:n] = log.heading[idx, t]
    out["static_length"][:n] = log.length[idx]
    out["static_width"][:n] = log.width[idx]
    return out


def _pedestrians(log: LoggedScenario, idx: np.ndarray, t: int, P: int) -> dict[str, np.ndarray]:
    f32 = np.float32
    out = {
        "ped_valid": np.zeros(P, bool),
        "ped_path": np.zeros((P, PED_POINTS, 2), f32),
        "ped_num_points": np.zeros(P, np.int32),
        "ped_speed": np.zeros(P, f32),
        "ped_start_time": np.zeros(P, f32),
        "ped_size": np.full((P, 2), 0.5, f32),
    }
    for k, i in enumerate(idx):
        fut = _future(log, int(i), t)
        span = np.flatnonzero(log.valid[i, t:])
        duration = max(float(span[-1]) * log.dt, log.dt)
        pts = fut[np.unique(np.linspace(0, len(fut) - 1, min(PED_POINTS, len(fut))).round().astype(int))]
        if len(pts) < 2:  # a standing pedestrian: a 1 cm path walked at almost no speed
            pts = np.stack([fut[0], fut[0] + [0.01, 0.0]])
        out["ped_valid"][k] = True
        out["ped_path"][k, : len(pts)] = pts
        out["ped_path"][k, len(pts) :] = pts[-1]
        out["ped_num_points"][k] = len(pts)
        out["ped_speed"][k] = max(_path_length(fut) / duration, 0.01)
        out["ped_size"][k] = (max(log.length[i], 0.3), max(log.width[i], 0.3))
    return out


class LogSpawner:
    """Spawner that always returns a copy of one fixed `Scenario` (for `VecEnv`)."""

    def __init__(self, scenario: Scenario) -> None:
        self.scenario = scenario

    def sample(self, road_map: Any, rng: np.random.Generator, map_index: int = 0) -> Scenario:
        import copy

        return copy.deepcopy(self.scenario)


def run_logged(
    log: LoggedScenario,
    policy: Any,
    others: str = "rule_based",
    start: int = 10,
    seed: int = 0,
    **scenario_kwargs: Any,
) -> tuple[WaymaxRecord, dict[str, np.ndarray]]:
    """Drive one logged scenario closed-loop and score the ego (module docstring).

    Args:
        log: The loaded scenario.
        policy: `policy(obs, env) -> (N, 2) actions`; only the ego's row (slot 0) is used.
        others: "rule_based" (default) or "log" (log replay of the other agents).
        start: Initial step (10).
        seed: Env seed.
        **scenario_kwargs: Passed to `build_scenario`.

    Returns:
        The `WaymaxRecord` and the rollout arrays (``ego_boxes`` (T, 5), ``ego_vel`` (T, 2),
        ``others`` (T, M, 5), ``others_valid`` (T, M)).
    """
    from selfplaydrive.eval.longform import RuleBasedPolicy
    from selfplaydrive.sim.vec_env import VecEnv

    if others not in ("rule_based", "log"):
        raise ValueError(f"others: expected 'rule_based' or 'log', got {others!r}")
    sc, lay = build_scenario(log, start=start, **scenario_kwargs)
    env = VecEnv(log.road_map, LogSpawner(sc), 1, seed=seed, terminated_vehicle="obstacle")
    obs = env.reset(seed=seed)
    driver = RuleBasedPolicy()
    T, A = log.num_steps, len(lay.agents)
    sim_boxes = np.zeros((T, A, 5))
    sim_speed = np.zeros((T, A))
    sim_valid = np.zeros((T, A), bool)
    _record(env, A, sim_boxes, sim_speed, sim_valid, start)
    for t in range(start + 1, T):
        act = np.asarray(driver(obs, env)).copy()
        act[0] = np.asarray(policy(obs, env))[0]
        env.step(act)
        obs = env.observations
        if int(env.state.step[0]) != t - start:
            raise RuntimeError(
                f"{log.path}: the world was reset at step {t} although its sentinel agent is active"
            )
        if others == "log":
            _replay(env, log, lay.agents[1:], t)
        _record(env, A, sim_boxes, sim_speed, sim_valid, t)
    return _score(log, lay, start, sim_boxes, sim_speed, sim_valid)


def _record(env: Any, A: int, boxes: np.ndarray, speed: np.ndarray, valid: np.ndarray, t: int) -> None:
    st = env.state
    boxes[t] = np.c_[st.x[:A], st.y[:A], st.length[:A], st.width[:A], st.heading[:A]]
    speed[t] = st.speed[:A]
    valid[t] = st.agent_valid[:A].astype(bool)


def _replay(env: Any, log: LoggedScenario, idx: np.ndarray, t: int) -> None:
    """Overwrite the pose and speed of agent slots 1.. with the log at step t (where valid)."""
    # an invalid log step keeps the agent's last pose; it is scored with the log's validity
    rows = [(slot, i) for slot, i in enumerate(idx, start=1) if log.valid[i, t]]
    if not rows:
        return
    slots, objs = np.array([r[0] for r in rows]), np.array([r[1] for r in rows])
    speed = [float(np.linalg.norm(log.vel[i, t])) for i in objs]
    env.set_poses(slots, log.xy[objs, t], log.heading[objs, t].astype(np.float64), speed)


def _log_boxes(log: LoggedScenario, idx: np.ndarray) -> np.ndarray:
    """(T, len(idx), 5) logged boxes."""
    shape = (log.num_steps, len(idx))
    size = [np.broadcast_to(v[idx], shape)[..., None] for v in (log.length, log.width)]
    return np.concatenate([log.xy[idx].transpose(1, 0, 2), *size, log.heading[idx].T[..., None]], axis=2)


def _score(log: LoggedScenario, lay: SceneLayout, start: int, sim_boxes, sim_speed, sim_valid):
    ego = int(lay.agents[0])
    hist = slice(0, start)
    ego_boxes = sim_boxes[:, 0].copy()
    ego_boxes[hist] = _log_boxes(log, lay.agents[:1])[hist, 0]
    ego_vel = sim_speed[:, 0, None] * np.c_[np.cos(sim_boxes[:, 0, 4]), np.sin(sim_boxes[:, 0, 4])]
    ego_vel[hist] = log.vel[ego, hist]
    ego_valid = sim_valid[:, 0].copy()
    ego_valid[hist] = log.valid[ego, hist]
    # other objects: simulated agents after start, log before; statics, peds and absent objects: log
    others = sim_boxes[:, 1:].copy()
    others_valid = sim_valid[:, 1:].copy()
    others[hist] = _log_boxes(log, lay.agents[1:])[hist]
    others_valid[hist] = log.valid[lay.agents[1:]].T[hist]
    rest = np.concatenate([lay.statics, lay.peds, lay.replay]).astype(np.int64)
    all_boxes = np.concatenate([others, _log_boxes(log, rest)], axis=1)
    all_valid = np.concatenate([others_valid, log.valid[rest].T], axis=1)
    statics_hold = slice(len(lay.agents) - 1, len(lay.agents) - 1 + len(lay.statics))
    all_valid[start:, statics_hold] = True  # static vehicles stand where they were at start
    all_boxes[start:, statics_hold] = all_boxes[start, statics_hold]
    edges = RoadEdges.from_polylines(log.edges) if log.edges else None
    rec = waymax_episode(
        ego_boxes, ego_vel, log.xy[ego], ego_valid=ego_valid, log_valid=log.valid[ego],
        others=all_boxes, others_valid=all_valid, edges=edges, start=start, dt=log.dt, scenario_id=log.name,
    )  # fmt: skip
    return rec, {"ego_boxes": ego_boxes, "ego_vel": ego_vel, "others": all_boxes, "others_valid": all_valid}


def evaluate_logged(
    paths: Sequence[str | Path], policy: Any, others: str = "rule_based", start: int = 10, **kwargs: Any
) -> dict[str, Any]:
    """Run `run_logged` on every file; returns {"records": [...], "aggregate": aggregate_waymax}."""
    records = [
        run_logged(load_gpudrive_json(p), policy, others=others, start=start, **kwargs)[0] for p in paths
    ]
    return {"records": [r.to_dict() for r in records], "aggregate": aggregate_waymax(records)}
