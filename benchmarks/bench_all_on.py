"""Cost of every issue #15 component at once (docs/benchmarks.md "Every new component on").

The whole step (`VecEnv.step`: physics, events, reward, observation, autoreset) of the paper
configuration against the same world with every component of issue #15 switched on: the four
rule reward terms (red_intersection, stop_sign, crosswalk_yield, wrong_way; docs/rewards.md),
the jerk-limited bicycle (`physics=jerk`) and one of the two new encoders (only one is active
at a time): `obs=rules` (STOP/YIELD lines, crosswalk occupancy) or `obs=partial` with occlusion
and every perception-noise effect on. Each variant is the `selfplaydrive bench` config with the
overrides below, stepped with random actions of its own action space; the parts are also
timed alone (the rule terms, the jerk model, each encoder) to show where the cost is.

Rounds alternate the variants (the order rotated each round) so that drift of a shared machine
hits every variant alike. Per round and variant: agent-steps (valid agents summed over the
timed steps) per CPU-second of this process and per wall-clock second; reported are the
medians over rounds and the median of the per-round ratios to the paper configuration.

Usage (pin to one core; one simulator thread):
    taskset -c 0 python benchmarks/bench_all_on.py [--worlds 8] [--steps 200] [--rounds 7] [--json]
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

from selfplaydrive.builder import build_env, compose

RULE_TERMS = ("red_intersection", "stop_sign", "crosswalk_yield", "wrong_way")
ALL_ON = ["physics=jerk", *(f"+reward.terms.{t}=1.0" for t in RULE_TERMS)]
NOISE = ["obs.pos_std=0.5", "obs.heading_std=0.05", "obs.speed_std=0.3", "obs.p_miss=0.05", "obs.fp_rate=0.5"]
VARIANTS: dict[str, list[str]] = {
    "paper": [],
    "all_on_rules": [*ALL_ON, "obs=rules"],
    "all_on_partial": [*ALL_ON, "obs=partial", "obs.occlusion=true", *NOISE],
    # the parts alone, to see where the cost is
    "rule_terms": list(ALL_ON[1:]),
    "jerk": ["physics=jerk"],
    "obs_rules": ["obs=rules"],
    "obs_partial_occlusion": ["obs=partial", "obs.occlusion=true"],
}


class Runner:
    """One variant's env and its pre-drawn random actions."""

    def __init__(self, overrides: list[str], worlds: int, steps: int, seed: int) -> None:
        cfg = compose("bench", [*overrides, f"env.num_worlds={worlds}", "env.num_threads=1", f"seed={seed}"])
        self.env = build_env(cfg)
        self.env.reset(seed)
        nvec = np.asarray(self.env.action_space.nvec)
        shape = (steps, self.env.num_agents, len(nvec))
        self.actions = np.random.default_rng(seed).integers(0, nvec, size=shape)

    def round(self, warmup: int) -> tuple[float, float]:
        """Agent-steps per CPU-second and per wall-clock second over the pre-drawn actions."""
        for a in self.actions[:warmup]:
            self.env.step(a)
        n = 0
        c0, t0 = time.process_time(), time.perf_counter()
        for a in self.actions[warmup:]:
            n += int(np.count_nonzero(self.env.masks))
            self.env.step(a)
        cpu, wall = time.process_time() - c0, time.perf_counter() - t0
        return n / cpu, n / wall


def measure(worlds: int, steps: int, warmup: int, rounds: int, seed: int) -> dict[str, dict[str, float]]:
    """Alternated rounds of every variant; medians over rounds and of per-round ratios."""
    runners = {k: Runner(v, worlds, steps + warmup, seed) for k, v in VARIANTS.items()}
    names = list(runners)
    cpu: dict[str, list[float]] = {k: [] for k in names}
    wall: dict[str, list[float]] = {k: [] for k in names}
    for r in range(rounds):
        for k in names[r % len(names) :] + names[: r % len(names)]:
            c, w = runners[k].round(warmup)
            cpu[k].append(c)
            wall[k].append(w)
    out = {}
    for k in names:
        ratios = [c / p for c, p in zip(cpu[k], cpu["paper"], strict=True)]
        out[k] = {
            "agent_steps_per_cpu_s": statistics.median(cpu[k]),
            "agent_steps_per_wall_s": statistics.median(wall[k]),
            "ns_per_agent_step_cpu": 1e9 / statistics.median(cpu[k]),
            "throughput_vs_paper": statistics.median(ratios),
            "ratio_min": min(ratios),
            "ratio_max": max(ratios),
        }
    return out


def table(result: dict[str, dict[str, float]]) -> str:
    """Markdown table of `measure`'s result."""
    lines = [
        "| variant | overrides | agent-steps / CPU-s | ns / agent-step (CPU) | agent-steps / wall-s "
        "| vs paper (min-max) |",
        "|---|---|---|---|---|---|",
    ]
    for k, v in result.items():
        over = " ".join(VARIANTS[k]) or "(paper configuration)"
        ratio = f"{v['throughput_vs_paper']:.3f} ({v['ratio_min']:.3f}-{v['ratio_max']:.3f})"
        lines.append(
            f"| {k} | `{over}` | {v['agent_steps_per_cpu_s']:,.0f} | {v['ns_per_agent_step_cpu']:,.0f} "
            f"| {v['agent_steps_per_wall_s']:,.0f} | {ratio} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    """Command-line entry point (see module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--worlds", type=int, default=8, help="worlds per env (32 agent slots each)")
    ap.add_argument("--steps", type=int, default=200, help="timed steps per round and variant")
    ap.add_argument("--warmup", type=int, default=20, help="untimed steps before each round")
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    result = measure(args.worlds, args.steps, args.warmup, args.rounds, args.seed)
    print(json.dumps(result, indent=1) if args.json else table(result))


if __name__ == "__main__":
    main()
