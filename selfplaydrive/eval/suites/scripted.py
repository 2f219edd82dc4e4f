"""Scripted drivers for the suites' classifier tests (paper section 5.3).

`ScriptedDriver` makes every agent follow a given polyline (pure pursuit through the bicycle
model of section 2.6) at a cruise speed, optionally holding still before an arc length until
a release time, or slowing to a crawl over a stretch. The plan builders below produce the
behaviours the classifiers must tell apart: a lane change right after the start versus a turn
from the wrong lane; yielding versus not yielding at a stop line or a crosswalk; waiting at a
red light, running it, or going around its line through the oncoming lane; a full, a rolling
or no stop at a stop sign.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from selfplaydrive.eval.suites.base import SuiteScenario
from selfplaydrive.eval.suites.red_lights import SWERVE
from selfplaydrive.eval.suites.shapes import offset_path
from selfplaydrive.maps.lane_paths import cumlen, cut, join, point_at, project

BRAKE = 3.0  # [m/s^2] deceleration used to stop at a hold point
ROLL_SPEED = 1.5  # [m/s] crawl of the rolling stop: between the stop and rolling thresholds


@dataclass
class Plan:
    """What one scripted agent does.

    Attributes:
        path: (n, 2) float64 polyline its centre follows [m].
        speed: Cruise speed [m/s].
        hold_arc: Arc length [m] along `path` where the centre stops, None for no stop.
        release_s: Time [s] from which the hold is lifted.
        slow: (from_arc, to_arc, speed): the centre is at most `speed` [m/s] from `from_arc` to
            `to_arc` [m] (braking at `BRAKE` before it), None for no slow stretch.
    """

    path: np.ndarray
    speed: float
    hold_arc: float | None = None
    release_s: float = float("inf")
    slow: tuple[float, float, float] | None = None


PlanFn = Callable[[SuiteScenario], Sequence[Plan | None]]


class ScriptedDriver:
    """Policy factory product for `run_suite`: `ScriptedDriver.factory(plan_fn)` gives
    `env -> driver`; `plan_fn(item)` returns one `Plan` (or None: brake) per agent slot."""

    def __init__(self, env, plan_fn: PlanFn) -> None:
        self.env, self.plan_fn = env, plan_fn
        self.plans: list[Sequence[Plan | None]] = []
        self.t = 0.0

    @staticmethod
    def factory(plan_fn: PlanFn) -> Callable[[object], ScriptedDriver]:
        return lambda env: ScriptedDriver(env, plan_fn)

    def begin(self, batch: Sequence[SuiteScenario]) -> None:
        self.plans = [self.plan_fn(item) for item in batch]
        self.t = 0.0

    def __call__(self, obs: np.ndarray | None = None) -> np.ndarray:
        st, A = self.env.state, self.env.agents_per_world
        accel = np.full(self.env.num_agents, -4.0)
        steer = np.zeros(self.env.num_agents)
        for w, plans in enumerate(self.plans):
            for a, plan in enumerate(plans):
                i = w * A + a
                if plan is None or not st.active[i]:
                    continue
                accel[i], steer[i] = _control(plan, st, i, self.t)
        self.t += float(self.env.params.dt)
        return _to_actions(self.env.action_table, accel, steer)


def _control(plan: Plan, st, i: int, t: float) -> tuple[float, float]:
    """Acceleration [m/s^2] and steering angle [rad] of agent row i."""
    xy = np.array([st.x[i], st.y[i]], dtype=np.float64)
    h, v, length = float(st.heading[i]), float(st.speed[i]), float(st.length[i])
    s = float(project(plan.path, xy[None])[0][0])
    target = plan.speed
    if plan.hold_arc is not None and t < plan.release_s:
        gap = max(plan.hold_arc - s, 0.0)
        target = min(target, np.sqrt(2.0 * BRAKE * gap)) if gap > 0.3 else 0.0
    if plan.slow is not None and s < plan.slow[1]:
        target = min(target, np.sqrt(plan.slow[2] ** 2 + 2.0 * BRAKE * max(plan.slow[0] - s, 0.0)))
    accel = float(np.clip(2.0 * (target - v), -4.0, 4.0))
    ld = max(4.0, 0.8 * v + 2.0)
    tgt, _ = point_at(plan.path, s + ld)
    dx, dy = tgt - xy
    alpha = np.arctan2(dy, dx) - h
    kappa = 2.0 * np.sin(alpha) / max(np.hypot(dx, dy), 1.0)
    wheelbase = 0.6 * length  # SimParams/physics default wheelbase_ratio (docs/world.md)
    beta = np.arcsin(np.clip(kappa * wheelbase / 2.0, -0.99, 0.99))
    return accel, float(np.arctan(2.0 * np.tan(beta)))


def _to_actions(table, accel: np.ndarray, steer: np.ndarray) -> np.ndarray:
    if table.discrete:
        ia = np.abs(accel[:, None] - table.accel[None, :]).argmin(axis=1)
        isteer = np.abs(steer[:, None] - table.steer[None, :]).argmin(axis=1)
        return np.stack([ia, isteer], axis=1).astype(np.int64)
    return np.clip(np.stack([accel, steer], axis=1), -table.high, table.high).astype(np.float32)


# -- plan builders -------------------------------------------------------------------------------
def _speed(item: SuiteScenario, slot: int = 0) -> float:
    return float(item.scenario.agent_speed[slot])


def turn_early_change(item: SuiteScenario) -> list[Plan]:
    """Turn lanes: move over to the correct lane within 15 m of the start, then turn."""
    corridor, start = item.paths["corridor"], item.scenario.agent_xy[0].astype(np.float64)
    s0 = float(project(corridor, start[None])[0][0])
    rest = cut(corridor, s0 + 15.0, cumlen(corridor)[-1])
    return [Plan(join([start[None], rest, item.paths["exit"]]), _speed(item))]


def turn_from_wrong_lane(item: SuiteScenario) -> list[Plan]:
    """Turn lanes: stay in the start lane up to the junction, then turn onto the exit lane."""
    corridor, wrong = item.paths["corridor"], item.paths["wrong"]
    entry, _ = point_at(corridor, item.info["entry_arc_m"])
    s_w = float(project(wrong, entry[None])[0][0])
    approach = cut(wrong, float(project(wrong, item.scenario.agent_xy[:1].astype(np.float64))[0][0]), s_w)
    exit_path = item.paths["exit"]
    p0, h0 = approach[-1], np.arctan2(*(approach[-1] - approach[-2])[::-1])
    p3, h3 = point_at(exit_path, 8.0)
    reach = np.hypot(*(p3 - p0)) / 2.0
    c1 = p0 + reach * np.array([np.cos(h0), np.sin(h0)])
    c2 = p3 - reach * np.array([np.cos(h3), np.sin(h3)])
    u = np.linspace(0.0, 1.0, 20)[:, None]
    curve = (1 - u) ** 3 * p0 + 3 * (1 - u) ** 2 * u * c1 + 3 * (1 - u) * u**2 * c2 + u**3 * p3
    rest = cut(exit_path, 8.0, cumlen(exit_path)[-1])
    return [Plan(join([approach, curve, rest]), min(_speed(item), 6.0))]


def stop_line_plans(yielder: str | None) -> PlanFn:
    """Stop lines: both keep their speed; `yielder` instead holds until 3 s after the
    constant-speed conflict time: "side" before its stop line, "main" 15 m before the
    conflict point (paths that merge converge well before it)."""

    def plans(item: SuiteScenario) -> list[Plan]:
        info = item.info
        out = []
        for slot, key in ((0, "main"), (1, "side")):
            plan = Plan(item.paths[key], float(info[f"{key}_speed_mps"]))
            if key == yielder:
                half = float(item.scenario.agent_length[slot]) / 2
                stop = info["stop_arc_m"] if key == "side" else info["main_conflict_arc_m"] - 15.0
                plan.hold_arc = stop - half - 1.0
                plan.release_s = info["time_to_conflict_s"] + 3.0
            out.append(plan)
        return out

    return plans


def crosswalk_plans(mode: str) -> PlanFn:
    """Crosswalks: "constant" keeps the initial speed, "slow" drives at 40 % of it, "stop"
    stops 2 m before the crosswalk for 6 s after the pedestrian's arrival time."""
    if mode not in ("constant", "slow", "stop"):
        raise ValueError(f"mode: expected 'constant', 'slow' or 'stop', got {mode!r}")

    def plans(item: SuiteScenario) -> list[Plan]:
        info = item.info
        v = _speed(item) * (0.4 if mode == "slow" else 1.0)
        plan = Plan(item.paths["ego"], v)
        if mode == "stop":
            plan.hold_arc = info["crosswalk_in_arc_m"] - info["ego_length_m"] / 2 - 2.0
            plan.release_s = info["ped_delay_s"] + info["ped_to_crossing_m"] / info["ped_speed_mps"] + 6.0
        return [plan]

    return plans


def red_light_plans(mode: str) -> PlanFn:
    """Red lights: "comply" holds its front 4 m before the line and waits (it stops ~2 m
    before: the controller overshoots a hold point by ~1.7 m from 8 m/s); "run" keeps
    its speed along its lane; "bypass" moves left onto the oncoming lane between `SWERVE` m
    (35 m and 15 m) before the line and drives on through the junction there (the paper's reward hack,
    section 5.1). Bypass needs the scenario's `oncoming_offset_m`."""
    if mode not in ("comply", "run", "bypass"):
        raise ValueError(f"mode: expected 'comply', 'run' or 'bypass', got {mode!r}")

    def plans(item: SuiteScenario) -> list[Plan]:
        info, path = item.info, item.paths["ego"]
        v, line = float(info["speed_mps"]), float(info["line_arc_m"])
        if mode == "comply":
            return [Plan(path, v, hold_arc=line - info["ego_length_m"] / 2 - 4.0)]
        if mode == "run":
            return [Plan(path, v)]
        if info["oncoming_offset_m"] is None:
            raise ValueError(f"bypass: scenario at light line {info['light_line']} has no oncoming lane")
        ramp = (line - SWERVE[0], line - SWERVE[1])
        return [Plan(offset_path(path, float(info["oncoming_offset_m"]), ramp), v)]

    return plans


def stop_sign_plans(mode: str) -> PlanFn:
    """Stop signs (slot 1 behind the line, slot 0 the cross traffic when present): "full"
    holds its front 3.5 m before the line (it stops ~2 m before it) until 5 s after the
    conflict time while the cross traffic keeps its speed; "rolling" crawls at `ROLL_SPEED`
    from 2 m before the line until its centre reaches it; "none" keeps its speed. In the last
    two the cross traffic waits 15 m before the conflict point until 10 s after the conflict
    time, so nobody collides."""
    if mode not in ("full", "rolling", "none"):
        raise ValueError(f"mode: expected 'full', 'rolling' or 'none', got {mode!r}")

    def plans(item: SuiteScenario) -> list[Plan | None]:
        info, sc = item.info, item.scenario
        T, line = float(info["time_to_conflict_s"]), float(info["stop_arc_m"])
        half = float(sc.agent_length[1]) / 2
        side = Plan(item.paths["side"], float(info["side_speed_mps"]))
        if mode == "full":
            side.hold_arc, side.release_s = line - half - 3.5, T + 5.0
        elif mode == "rolling":
            side.slow = (line - half - 2.0, line, ROLL_SPEED)
        if not sc.agent_valid[0]:
            return [None, side]
        main = Plan(item.paths["main"], float(info["main_speed_mps"]))
        if mode != "full":
            main.hold_arc = info["main_conflict_arc_m"] - 15.0 - float(sc.agent_length[0]) / 2
            main.release_s = T + 10.0
        return [main, side]

    return plans
