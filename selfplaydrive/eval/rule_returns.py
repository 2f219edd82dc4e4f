"""Does the reward still pay for breaking a rule? Returns of the rule suites' scripted drivers.

The paper's policies exploited loopholes of their reward (section 5.1): they passed red lights
through the oncoming lane, whose approach has no red line to touch; they did not stop at stop
signs, which the reward treats as yield lines; they yielded to only some crossing pedestrians
(section 5.3). Each failure mode is a `Loophole` here: a suite of constructed scenarios
(selfplaydrive/eval/suites) and scripted drivers that obey or break the rule in them. Driving
every driver through the same scenarios under a reward configuration (Hydra overrides of the
train config, the env built as for training) and comparing their mean returns shows whether
the reward prefers the compliant driver: a loophole is *closed* when every rule-breaking driver
earns strictly less than the compliant one.

Every agent carries the evaluation coefficients of paper section 5 (every coefficient at its
maximum), so returns differ only by what the drivers did. The drivers need continuous control,
so the env uses `ContinuousActions` whatever the configuration says (the reward does not depend
on the action space). `benchmarks/reward_landscape.py --rules` prints the table.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from selfplaydrive.eval.suites import scripted
from selfplaydrive.eval.suites.base import SuiteScenario, run_suite
from selfplaydrive.eval.suites.crosswalks import CrosswalkSuite
from selfplaydrive.eval.suites.red_lights import SWERVE, RedLightSuite
from selfplaydrive.eval.suites.report import generate_all
from selfplaydrive.eval.suites.shapes import offset_path
from selfplaydrive.eval.suites.stop_signs import StopSignSuite
from selfplaydrive.maps.roadmap import RoadMap, StopKind
from selfplaydrive.maps.rule_geometry import GATE_DEPTH


@dataclass(frozen=True)
class Driver:
    """A scripted driver of a loophole.

    Attributes:
        name: Label in the table.
        plans: Plan builder of `selfplaydrive.eval.suites.scripted`.
        compliant: It obeys the rule (the reference the others are compared with).
    """

    name: str
    plans: scripted.PlanFn
    compliant: bool = False


@dataclass(frozen=True)
class Loophole:
    """A failure mode: its suite, the slot the drivers are judged on, and the drivers.

    Attributes:
        name: Failure mode, named after the reward term that closes it.
        suite: Factory of the suite that builds and classifies the scenarios.
        slot: Agent slot whose return counts (the stop-sign suite's side vehicle is slot 1).
        drivers: The compliant driver first, then the rule breakers.
        usable: Scenarios every driver can drive (the bypass needs an oncoming lane).
    """

    name: str
    suite: Callable[[], Any]
    slot: int
    drivers: tuple[Driver, ...]
    usable: Callable[[SuiteScenario], bool] = field(default=lambda item: True)


def _has_oncoming(item: SuiteScenario) -> bool:
    return item.info.get("oncoming_offset_m") is not None


REJOIN = 12.0  # [m] over which the bypass swerves back into its lane after the controlled area


def swerve_path(
    path: np.ndarray, offset: float, out: tuple[float, float], back: tuple[float, float]
) -> np.ndarray:
    """`path` shifted `offset` [m] to the left between arcs `out` and `back` [m]: the shift
    grows smoothly (cosine) from 0 to `offset` over `out` and falls back to 0 over `back`.

    Returns:
        (n, 2) float64 polyline resampled every 0.5 m.
    """
    return offset_path(path, offset, out, back=back)


def bypass_and_rejoin(item: SuiteScenario) -> list[scripted.Plan]:
    """Red lights: the suite's oncoming-lane bypass (`scripted.red_light_plans("bypass")`) that
    swerves back into its own lane over `REJOIN` m after the controlled area, so it goes on
    along its route and collects its waypoints, as the paper's policy did (section 5.1)."""
    info, path = item.info, item.paths["ego"]
    if info["oncoming_offset_m"] is None:
        raise ValueError(f"bypass: scenario at light line {info['light_line']} has no oncoming lane")
    line = float(info["line_arc_m"])
    out = (line - SWERVE[0], line - SWERVE[1])
    back = (line + GATE_DEPTH, line + GATE_DEPTH + REJOIN)
    shifted = swerve_path(path, float(info["oncoming_offset_m"]), out, back)
    return [scripted.Plan(shifted, float(info["speed_mps"]))]


_COMPLY = Driver("comply", scripted.red_light_plans("comply"), compliant=True)
_BYPASS = Driver("bypass", bypass_and_rejoin)

LOOPHOLES: dict[str, Loophole] = {
    loop.name: loop
    for loop in (
        Loophole(  # section 5.1 "Red Lights": around the stop line through the oncoming lane
            "red_intersection",
            RedLightSuite,
            0,
            (_COMPLY, _BYPASS, Driver("run", scripted.red_light_plans("run"))),
            _has_oncoming,
        ),
        Loophole(  # section 5.1 "Stop Signs": the reward treats STOP lines as yield lines
            "stop_sign",
            lambda: StopSignSuite(kinds=("stop",)),
            1,
            (
                Driver("full_stop", scripted.stop_sign_plans("full"), compliant=True),
                Driver("rolling_stop", scripted.stop_sign_plans("rolling")),
                Driver("no_stop", scripted.stop_sign_plans("none")),
            ),
        ),
        Loophole(  # section 5.3: yielding to a crossing pedestrian
            "crosswalk_yield",
            lambda: CrosswalkSuite(variants=("crossing",)),
            0,
            (
                Driver("yield", scripted.crosswalk_plans("stop"), compliant=True),
                Driver("no_yield", scripted.crosswalk_plans("constant")),
            ),
        ),
        Loophole(  # section 5.1: the same bypass, seen as driving against the lane's direction
            "wrong_way", RedLightSuite, 0, (_COMPLY, _BYPASS), _has_oncoming
        ),
    )
}


@dataclass
class DriverResult:
    """One driver of one loophole, over the loophole's scenarios.

    Attributes:
        loophole: `Loophole.name`.
        driver: `Driver.name`.
        compliant: The driver obeys the rule.
        returns: (n,) return of the judged slot per scenario (sum of its rewards).
        terms: Per reward term (`VecEnv.term_names`), (n,) the term's share of each return.
        outcomes: (n,) the suite's outcome per scenario.
    """

    loophole: str
    driver: str
    compliant: bool
    returns: np.ndarray
    terms: dict[str, np.ndarray]
    outcomes: list[str]

    @property
    def return_mean(self) -> float:
        """Mean return over the scenarios (nan without any)."""
        return float(self.returns.mean()) if len(self.returns) else float("nan")

    def term_means(self) -> dict[str, float]:
        """Mean of every term's share of the return."""
        return {k: float(v.mean()) if len(v) else float("nan") for k, v in self.terms.items()}

    def outcome_counts(self) -> dict[str, int]:
        """How often each outcome occurred."""
        out: dict[str, int] = {}
        for o in self.outcomes:
            out[o] = out.get(o, 0) + 1
        return out


def with_stop_signs(road_map: RoadMap) -> RoadMap:
    """A copy of `road_map` whose stop lines are all STOP lines, for a map that has none (all
    YIELD); any other map (the bundled town, Tartu) is returned as it is."""
    kinds = np.asarray(road_map.stop_kind)
    if len(kinds) == 0 or np.any(kinds == StopKind.STOP):
        return road_map
    return dataclasses.replace(road_map, stop_kind=np.full_like(kinds, StopKind.STOP))


class _ReturnRecorder:
    """A `VecEnv` seen through `run_suite`, summing every world's rewards over its first
    episode (the worlds `run_suite` records; an autoreset world's next episode is not counted).

    Each `reset` starts a new batch; `batches` holds the sums of the batches before.
    """

    def __init__(self, env: Any) -> None:
        self._env = env
        self.batches: list[tuple[np.ndarray, np.ndarray]] = []
        self._running: np.ndarray | None = None

    def __getattr__(self, name: str) -> Any:
        return getattr(self._env, name)

    def reset(self, seed: int | None = None) -> np.ndarray:
        env = self._env
        W, A, M = env.num_worlds, env.agents_per_world, len(env.term_names)
        self.batches.append((np.zeros((W, A)), np.zeros((W, A, M))))
        self._running = np.ones(W, bool)
        return env.reset(seed=seed)

    def step(self, actions: np.ndarray) -> None:
        env, running = self._env, self._running
        assert running is not None, "reset before step"
        env.step(actions)
        W, A = env.num_worlds, env.agents_per_world
        counted = running[:, None] & env.reward_mask.reshape(W, A)
        total, terms = self.batches[-1]
        total += np.where(counted, env.rewards.reshape(W, A), 0.0)
        terms += np.where(counted[..., None], env.reward_terms.reshape(W, A, -1), 0.0)
        running &= env.state.step[:W] != 0  # as run_suite: an autoreset world starts at step 0

    def per_scenario(self, sizes: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
        """(n, A) returns and (n, A, M) term sums, the first `sizes[b]` worlds of batch b."""
        if len(sizes) != len(self.batches):
            raise RuntimeError(f"expected {len(sizes)} batches, recorded {len(self.batches)}")
        total = np.concatenate([t[:n] for (t, _), n in zip(self.batches, sizes, strict=True)])
        terms = np.concatenate([m[:n] for (_, m), n in zip(self.batches, sizes, strict=True)])
        return total, terms


EnvFactory = Callable[[Any, int], Any]


def drive(
    env_factory: EnvFactory,
    loophole: Loophole,
    driver: Driver,
    items: Sequence[SuiteScenario],
    batch_size: int = 16,
    seed: int = 0,
) -> DriverResult:
    """Drive `items` with `driver` and classify them with the loophole's suite.

    Args:
        env_factory: `(spawner, num_worlds) -> VecEnv` (see `run_suite`).
        loophole: The failure mode (its suite classifies, its `slot` is judged).
        driver: One of `loophole.drivers`.
        items: The scenarios (from the loophole's suite, all `usable`).
        batch_size: Worlds stepped together.
        seed: Seed of the env resets.
    """
    if len(items) == 0:
        return DriverResult(loophole.name, driver.name, driver.compliant, np.zeros(0), {}, [])
    recorders: list[_ReturnRecorder] = []

    def factory(spawner: Any, num_worlds: int) -> _ReturnRecorder:
        recorders.append(_ReturnRecorder(env_factory(spawner, num_worlds)))
        return recorders[-1]

    trajs = run_suite(factory, scripted.ScriptedDriver.factory(driver.plans), items, batch_size, seed=seed)
    suite = loophole.suite()
    outcomes = [str(suite.classify(i, t)["outcome"]) for i, t in zip(items, trajs, strict=True)]
    W = min(int(batch_size), len(items))
    sizes = [min(W, len(items) - start) for start in range(0, len(items), W)]
    total, terms = recorders[0].per_scenario(sizes)
    names = list(recorders[0].term_names)
    s = loophole.slot
    return DriverResult(
        loophole.name,
        driver.name,
        driver.compliant,
        total[:, s],
        {k: terms[:, s, j] for j, k in enumerate(names)},
        outcomes,
    )


def scenarios(loophole: Loophole, maps: Sequence[RoadMap], count: int, seed: int = 0) -> list[SuiteScenario]:
    """Up to `count` usable scenarios of the loophole's suite on `maps` (split evenly over them;
    three times as many are asked for so the unusable ones can be dropped; the suite's warning
    that a map offers fewer is silenced: the result's length shows it)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        items = generate_all(loophole.suite(), maps, 3 * int(count), np.random.default_rng(seed))
    return [it for it in items if loophole.usable(it)][: int(count)]


def compare(
    cfg: Any,
    names: Sequence[str] | None = None,
    count: int = 4,
    seed: int = 0,
    batch_size: int = 16,
    maps: Sequence[RoadMap] | None = None,
) -> list[DriverResult]:
    """Every driver of every loophole in `names` under the reward of `cfg`.

    Args:
        cfg: A composed train config (`selfplaydrive.builder.compose`): its map, reward terms,
            env parameters, physics and observation build the env; its spawner is replaced by
            the suites' scenarios.
        names: Loopholes to run (keys of `LOOPHOLES`), default all.
        count: Scenarios per loophole (the stop-sign suite runs each conflict with and without
            cross traffic: twice as many).
        seed: Seed of scenario generation and env resets.
        batch_size: Worlds stepped together.
        maps: The maps (default: built from `cfg.map`). A map without STOP lines gets its
            stop lines relabelled STOP for the stop-sign loophole (`with_stop_signs`).

    Raises:
        ValueError: An unknown loophole name, or `count` below 1.
    """
    from selfplaydrive.builder import build_env, build_maps
    from selfplaydrive.sim.actions import ContinuousActions

    names = list(LOOPHOLES) if names is None else list(names)
    unknown = [n for n in names if n not in LOOPHOLES]
    if unknown:
        raise ValueError(f"names: unknown loophole(s) {unknown}, expected names among {sorted(LOOPHOLES)}")
    if int(count) < 1:
        raise ValueError(f"count: expected an integer >= 1, got {count!r}")
    base = list(build_maps(cfg.map) if maps is None else maps)
    out: list[DriverResult] = []
    for name in names:
        loophole = LOOPHOLES[name]
        used = [with_stop_signs(m) for m in base] if name == "stop_sign" else base

        def env_factory(spawner: Any, num_worlds: int, used: list[RoadMap] = used) -> Any:
            kwargs = {"maps": used, "spawner": spawner, "num_worlds": num_worlds, "num_threads": 1}
            return build_env(cfg, actions=ContinuousActions(), **kwargs)

        items = scenarios(loophole, used, count, seed)
        out.extend(drive(env_factory, loophole, d, items, batch_size, seed) for d in loophole.drivers)
    return out


def closed(results: Sequence[DriverResult]) -> dict[str, bool]:
    """Per loophole: every rule-breaking driver's mean return is strictly below the compliant
    driver's (False when a loophole has no scenarios)."""
    out: dict[str, bool] = {}
    for name in dict.fromkeys(r.loophole for r in results):
        rows = [r for r in results if r.loophole == name]
        ref = [r.return_mean for r in rows if r.compliant]
        others = [r.return_mean for r in rows if not r.compliant]
        out[name] = bool(ref and others and all(o < min(ref) for o in others))
    return out


def table(results: Sequence[DriverResult], terms: Sequence[str] | None = None) -> str:
    """Markdown table: loophole, driver, scenarios, mean return, the mean share of each term in
    `terms` (default: every term that is non-zero for some driver) and the outcomes."""
    if terms is None:
        seen: dict[str, None] = {}
        for r in results:
            for k, v in r.term_means().items():
                if v != 0.0:
                    seen[k] = None
        terms = list(seen)
    head = ["loophole", "driver", "n", "return", *terms, "outcomes"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in results:
        means = r.term_means()
        outcomes = ", ".join(f"{k} {v}" for k, v in sorted(r.outcome_counts().items()))
        cells = [r.loophole, r.driver, str(len(r.returns)), f"{r.return_mean:+.3f}"]
        cells += [f"{means[k]:+.3f}" if k in means else "-" for k in terms]
        lines.append("| " + " | ".join([*cells, outcomes]) + " |")
    return "\n".join(lines)
