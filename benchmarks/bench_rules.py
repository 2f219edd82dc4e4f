"""Cost of the rule reward terms of issues #15 and #16 (docs/benchmarks.md "Rule reward terms").

Two envs on the bundled town, stepped with the same random actions (rewards do not change the
dynamics, so both follow the same trajectories): the paper configuration and the paper's
eight terms plus the rule terms (`RULES`). Rounds alternate
between the two so that drift of a shared machine hits both alike. Reported per agent-step
(medians of per-step times within a round, then the median over rounds): the whole step
(`profile=False`) and the reward stage alone (a second pair of envs with `profile=True`).
``--each`` measures each rule term alone against the paper's terms (``--only NAME``: that one).

Usage:
    python benchmarks/bench_rules.py [--worlds 8] [--steps 200] [--rounds 5] [--threads 1] [--json]
    python benchmarks/bench_rules.py --each [--only turn_lane] [--worlds 8] [--steps 200] [--rounds 5]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from selfplaydrive.maps.loader import load_map
from selfplaydrive.rewards import TERM_NAMES, LinearReward
from selfplaydrive.scenario.spawner import PaperSpawner
from selfplaydrive.sim.vec_env import VecEnv

RULES = ("red_intersection", "stop_sign", "crosswalk_yield", "wrong_way", "turn_lane")


def make(road_map, rules: bool | str, worlds: int, threads: int, profile: bool) -> VecEnv:
    """The paper's terms, plus all rule terms (True) or one of them (its name)."""
    extra = RULES if rules is True else (rules,) if rules else ()
    weights = {n: 1.0 for n in TERM_NAMES} | {n: 1.0 for n in extra}
    env = VecEnv(
        road_map,
        PaperSpawner(),
        worlds,
        seed=0,
        num_threads=threads,
        reward=LinearReward(weights),
        profile=profile,
    )
    env.reset(0)
    return env


def run(env: VecEnv, actions: list[np.ndarray]) -> tuple[float, float]:
    """Median whole-step and reward-stage time per agent-step [us] over `actions`."""
    steps, stage = [], []
    for a in actions:
        before = env._world.timings["reward"]
        t0 = time.perf_counter()
        env.step(a)
        steps.append(time.perf_counter() - t0)
        stage.append(env._world.timings["reward"] - before)
    n = env.num_agents
    return statistics.median(steps) / n * 1e6, statistics.median(stage) / n * 1e6


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--worlds", type=int, default=8)
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--each", action="store_true", help="reward stage of each rule term alone")
    ap.add_argument("--only", choices=RULES, help="with --each: this rule term only")
    args = ap.parse_args()
    town = load_map("default")
    if args.each:
        each(town, args)
        return
    envs = {
        (rules, prof): make(town, rules, args.worlds, args.threads, prof)
        for rules in (False, True)
        for prof in (False, True)
    }
    rng = np.random.default_rng(0)
    n = envs[(False, False)].num_agents
    res: dict[str, list[float]] = {
        k: [] for k in ("paper_step", "rules_step", "paper_reward", "rules_reward")
    }
    for r in range(args.rounds):
        acts = [np.stack([rng.integers(0, 7, n), rng.integers(0, 13, n)], axis=1) for _ in range(args.steps)]
        order = (False, True) if r % 2 == 0 else (True, False)
        for rules in order:
            name = "rules" if rules else "paper"
            res[f"{name}_step"].append(run(envs[(rules, False)], acts)[0])
            res[f"{name}_reward"].append(run(envs[(rules, True)], acts)[1])
    med = {k: statistics.median(v) for k, v in res.items()}
    out = {
        "worlds": args.worlds,
        "agents_per_world": envs[(False, False)].agents_per_world,
        "threads": args.threads,
        "steps_per_round": args.steps,
        "rounds": args.rounds,
        "us_per_agent_step": med,
        "step_ratio": med["rules_step"] / med["paper_step"],
        "rules_reward_extra_us": med["rules_reward"] - med["paper_reward"],
    }
    if args.json:
        print(json.dumps(out, indent=2))
        return
    print(
        f"{args.worlds} worlds x {out['agents_per_world']} agents, {args.threads} thread(s), "
        f"{args.rounds} rounds x {args.steps} steps (medians) [us per agent-step]"
    )
    for k, v in med.items():
        print(f"  {k:14s} {v:8.3f}")
    print(f"  whole step with the rule terms / paper: {out['step_ratio']:.3f}")
    print(
        f"  reward stage: +{out['rules_reward_extra_us']:.3f} us per agent-step "
        f"for the {len(RULES)} rule terms"
    )


def each(town, args: argparse.Namespace) -> None:
    """Reward stage and whole step (profiled envs) per agent-step of the paper's terms plus one
    rule term, for each (rotated order per round), and the extra cost over the paper's terms."""
    rules = (args.only,) if args.only else RULES
    variants: list[bool | str] = [False, *rules]
    envs = {v: make(town, v, args.worlds, args.threads, True) for v in variants}
    rng = np.random.default_rng(0)
    n = envs[False].num_agents
    res: dict[bool | str, list[tuple[float, float]]] = {v: [] for v in variants}
    for r in range(args.rounds):
        acts = [np.stack([rng.integers(0, 7, n), rng.integers(0, 13, n)], axis=1) for _ in range(args.steps)]
        for v in variants[r % len(variants) :] + variants[: r % len(variants)]:
            res[v].append(run(envs[v], acts))
    step = {v: statistics.median(t[0] for t in res[v]) for v in variants}
    stage = {v: statistics.median(t[1] for t in res[v]) for v in variants}
    print(
        f"[us per agent-step], {args.worlds} worlds x {envs[False].agents_per_world} agents, "
        f"medians of {args.rounds} rounds x {args.steps} steps (profiled envs):"
    )
    print(f"  {'terms':18s} {'reward stage':>12s} {'whole step':>10s} {'agent-steps/s':>13s}")
    for v in variants:
        label = f"+ {v}" if v else "paper terms"
        extra = f"  (stage +{stage[v] - stage[False]:.4f}, step x{step[v] / step[False]:.3f})" if v else ""
        print(f"  {label:18s} {stage[v]:12.4f} {step[v]:10.4f} {1e6 / step[v]:13.0f}{extra}")


if __name__ == "__main__":
    main()
