"""Returns of scripted drivers under a reward setting: is driving worth more than standing still?

Runs the built-in drivers (rule-based lane following, standing still, random, and "keep the
initial speed and heading") on the bundled town and prints waypoint completion, mean agent
return, event rates and the per-term return. It explains the main job's settings
(conf/experiment/laptop.yaml, docs/training.md "The main job"): under the paper's reward a
competent rule-based driver earns less than a car that stands still, so a policy that has not
yet learned to steer is pushed towards stopping.

    python benchmarks/reward_landscape.py                      # the main job's settings
    python benchmarks/reward_landscape.py experiment=null      # the paper's reward
    python benchmarks/reward_landscape.py experiment=null env.params.terminate_threshold=0
"""

from __future__ import annotations

import argparse

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
    args = parser.parse_args()
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


if __name__ == "__main__":
    main()
