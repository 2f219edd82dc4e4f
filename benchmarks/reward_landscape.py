"""Returns of scripted drivers under a reward setting: is driving worth more than standing still?

Runs the built-in drivers (rule-based lane following, standing still, random, and "keep the
initial speed and heading") on the bundled town and prints waypoint completion, mean agent
return, event rates and the per-term return. It explains the main job's settings
(conf/experiment/laptop.yaml, docs/training.md "The main job"): under the paper's reward a
competent rule-based driver earns less than a car that stands still, so a policy that has not
yet learned to steer is pushed towards stopping.

    python benchmarks/reward_landscape.py                      # the main job's settings
    python benchmarks/reward_landscape.py '~experiment'        # the paper's reward
    python benchmarks/reward_landscape.py '~experiment' reward.terminate_threshold=0

With --rules it asks instead whether the reward pays for breaking a rule (paper sections 5.1,
5.3; selfplaydrive/eval/rule_returns.py): the rule suites' scripted drivers (red light: wait,
bypass through the oncoming lane, run it; stop sign: full, rolling, no stop; crosswalk: yield
or not; wrong way: the bypass) drive the suites' constructed scenarios, and the table gives
each driver's mean return, per-term returns and the suite's outcomes; a loophole is closed when
every rule breaker earns strictly less than the compliant driver (docs/analyses.md, "Closing
the loopholes").

    python benchmarks/reward_landscape.py --rules                           # the main job
    python benchmarks/reward_landscape.py --rules experiment=fix_all        # with the fixes
    python benchmarks/reward_landscape.py --rules experiment=fix_red_light map=tartu --count 8
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from selfplaydrive.builder import build_env, compose
from selfplaydrive.drivers import RandomDriver, RuleBasedDriver, StaticDriver
from selfplaydrive.trainers.ppo.episodes import EpisodeTracker, summarize


class KeepSpeedDriver:
    """Zero acceleration and zero steering: the middle choice of each action dimension."""

    def __init__(self, env) -> None:
        self.actions = np.asarray(env.action_space.nvec, dtype=np.int64)[None, :] // 2
        self.num_agents = env.num_agents

    def act(self) -> np.ndarray:
        return np.repeat(self.actions, self.num_agents, axis=0)


DRIVERS = {
    "rule_based": RuleBasedDriver,
    "static": StaticDriver,
    "random": RandomDriver,
    "keep_speed": KeepSpeedDriver,
}
SHOWN = ("episodes", "waypoint_completion", "return_mean", "collision_rate", "offroad_rate", "km")


def run(overrides: list[str], worlds: int, steps: int, seed: int) -> dict[str, dict[str, float]]:
    """Summaries (episodes.summarize) of every driver over `steps` env steps from one reset."""
    out = {}
    for name, driver_cls in DRIVERS.items():
        env = build_env(compose("train", [f"env.num_worlds={worlds}", *overrides]))
        env.reset(seed=seed)
        driver, tracker = driver_cls(env), EpisodeTracker(env)
        tracker.on_reset()
        records, returns = [], []
        for _ in range(steps):
            acted = env.masks.copy()
            env.step(driver.act())
            tracker.on_step(acted)
            r, g = tracker.pop()
            records += r
            returns += g
        out[name] = summarize(records, returns)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("overrides", nargs="*", help="Hydra overrides of the train config")
    parser.add_argument("--worlds", type=int, default=8)
    parser.add_argument("--steps", type=int, default=400, help="env steps (0.1 s each)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--rules", action="store_true", help="the rule loopholes' scripted drivers")
    parser.add_argument("--count", type=int, default=8, help="--rules: scenarios per loophole")
    parser.add_argument("--loopholes", default=None, help="--rules: comma-separated names (default all)")
    args = parser.parse_args()
    if args.rules:
        rules(args)
        return
    results = run(args.overrides, args.worlds, args.steps, args.seed)
    print(f"overrides: {' '.join(args.overrides) or '(none)'}; {args.worlds} worlds x {args.steps} steps")
    print("| driver | " + " | ".join(SHOWN) + " |")
    print("|---" * (len(SHOWN) + 1) + "|")
    for name, s in results.items():
        print(f"| {name} | " + " | ".join(f"{s.get(k, float('nan')):.3g}" for k in SHOWN) + " |")
    terms = sorted(k for k in next(iter(results.values())) if k.startswith("term/"))
    print("\nper-term return (mean per agent):")
    for name, s in results.items():
        print(f"  {name:11s} " + ", ".join(f"{k[5:]} {s[k]:+.3f}" for k in terms))


def missing_map(cfg) -> str | None:
    """The map file of `cfg.map` when it is a path that does not exist (the Tartu map lives in
    ../shared/maps, present only in the project's CI), else None."""
    spec = str(cfg.map.get("spec", "")) if hasattr(cfg.map, "get") else ""
    return spec if spec.endswith((".osm", ".xodr", ".xml", ".npz")) and not Path(spec).exists() else None


def rules(args) -> None:
    """--rules: print `rule_returns.compare`'s table for the overrides' reward."""
    from selfplaydrive.eval import rule_returns

    cfg = compose("train", args.overrides)
    path = missing_map(cfg)
    if path is not None:
        print(f"skipped: map file {path} not present (../shared/maps is only available in the project's CI)")
        return
    names = args.loopholes.split(",") if args.loopholes else None
    results = rule_returns.compare(cfg, names, args.count, args.seed)
    shown = " ".join(args.overrides) or "(none)"
    print(f"overrides: {shown}; {args.count} scenarios per loophole, seed {args.seed}")
    print(rule_returns.table(results))
    verdict = rule_returns.closed(results)
    print(
        "\nclosed (every rule breaker earns less than the compliant driver): "
        + ", ".join(f"{k} {'yes' if v else 'NO'}" for k, v in verdict.items())
    )
    sys.stdout.flush()


if __name__ == "__main__":
    main()
