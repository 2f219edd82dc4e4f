"""`run_all_suites`: generate, drive, classify and aggregate every rule-adherence suite of paper
section 5.3 in one call, with JSON-ready results (for `selfplaydrive eval`)."""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from selfplaydrive.eval.suites.base import PolicyFactory, SuiteScenario, run_suite
from selfplaydrive.eval.suites.crosswalks import CrosswalkSuite
from selfplaydrive.eval.suites.stop_lines import StopLineSuite, compare_runs
from selfplaydrive.eval.suites.turn_lanes import TurnLaneSuite
from selfplaydrive.maps.roadmap import RoadMap

PAPER_COUNTS = {"turn_lanes": 128, "stop_lines": 63, "crosswalks": 64}  # section 5.3


def default_suites() -> dict[str, Any]:
    """The three suites with their default settings, by name."""
    return {"turn_lanes": TurnLaneSuite(), "stop_lines": StopLineSuite(), "crosswalks": CrosswalkSuite()}


def generate_all(suite, maps: Sequence[RoadMap], count: int, rng: np.random.Generator) -> list[SuiteScenario]:
    """`count` scenarios of `suite` split evenly over `maps` (map m's share first come first)."""
    out: list[SuiteScenario] = []
    for m, road_map in enumerate(maps):
        share = count // len(maps) + (1 if m < count % len(maps) else 0)
        if share:
            out.extend(suite.generate(road_map, rng, share, map_index=m))
    return out


def run_all_suites(
    maps: RoadMap | Sequence[RoadMap],
    policy: PolicyFactory,
    counts: Mapping[str, int] | None = None,
    seed: int = 0,
    batch_size: int = 32,
    env_factory: Callable[..., Any] | None = None,
    suites: Mapping[str, Any] | None = None,
    progress: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Run the suites named in `counts` and return their results.

    Args:
        maps: The map(s) to build scenarios on (counts are split evenly over them).
        policy: Factory `policy(env) -> act` (see `run_suite`), e.g. `RuleBasedDriver`.
        counts: Scenarios per suite (sites for the crosswalk suite, each run in both variants);
            default `PAPER_COUNTS`. A suite left out is not run.
        seed: Seed of scenario generation and env resets.
        batch_size: Worlds stepped together.
        env_factory: `(spawner, num_worlds) -> VecEnv` for non-default env settings.
        suites: Suite objects by name (default `default_suites()`).
        progress: Called with a one-line status before and after each suite (scenarios,
            wall time); None is silent.

    Returns:
        {suite: {"requested", "generated", "summary", "scenarios": [{"info", "result"}]}}; the
        stop-line entry has "summary" (stop lines observed), "hidden_summary" (stop lines masked
        from the observation), "changed" (`compare_runs`) and per scenario "result_hidden".
    """
    maps = [maps] if isinstance(maps, RoadMap) else list(maps)
    counts = dict(PAPER_COUNTS if counts is None else counts)
    suites = dict(default_suites() if suites is None else suites)
    unknown = sorted(set(counts) - set(suites))
    if unknown:
        raise ValueError(f"counts: unknown suite(s) {unknown}, expected names among {sorted(suites)}")
    env = env_factory if env_factory is not None else maps
    root = np.random.default_rng(seed)
    out: dict[str, Any] = {}
    say = progress or (lambda _msg: None)
    for name in sorted(counts):
        suite, rng = suites[name], np.random.default_rng(root.integers(2**63 - 1))
        start = time.perf_counter()
        items = generate_all(suite, maps, int(counts[name]), rng)
        runs = "2 runs (stop lines shown, hidden)" if name == "stop_lines" else "1 run"
        say(f"suites: {name}: {len(items)} scenarios generated (count={int(counts[name])}), {runs} ...")
        out[name] = _run_one(name, suite, items, int(counts[name]), env, policy, batch_size, seed)
        say(f"suites: {name}: done in {time.perf_counter() - start:.1f} s")
    return out


def _run_one(
    name: str,
    suite: Any,
    items: list[SuiteScenario],
    requested: int,
    env: Any,
    policy: PolicyFactory,
    batch_size: int,
    seed: int,
) -> dict[str, Any]:
    """Drive and classify one suite's scenarios (the stop-line suite twice, see `run_all_suites`)."""
    results = [
        suite.classify(i, t)
        for i, t in zip(items, run_suite(env, policy, items, batch_size, seed=seed), strict=True)
    ]
    entry: dict[str, Any] = {
        "requested": requested,
        "generated": len(items),
        "summary": suite.summarise(results),
        "scenarios": [{"info": i.info, "result": r} for i, r in zip(items, results, strict=True)],
    }
    if name == "stop_lines":
        trajs = run_suite(env, policy, items, batch_size, hide_stop_lines_obs=True, seed=seed)
        hidden = [suite.classify(i, t) for i, t in zip(items, trajs, strict=True)]
        entry["hidden_summary"] = suite.summarise(hidden)
        entry["changed"] = compare_runs(results, hidden)
        for row, r in zip(entry["scenarios"], hidden, strict=True):
            row["result_hidden"] = r
    return entry
