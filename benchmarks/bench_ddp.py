"""Both cores for training: the main job as one process against two data-parallel ranks
(torchrun, Gloo), taking turns in one run (docs/benchmarks.md, "Trainer: both cores").

    python benchmarks/bench_ddp.py                       # the main job's settings, 3 rounds
    python benchmarks/bench_ddp.py --rounds 5 --slot-steps 1000000 '~experiment' trainer.torch_threads=1

Each round trains the same config twice, in the order single/ranks then ranks/single in the
next round: once as `selfplaydrive train` (one process: one torch thread, one env thread, all
`env.num_worlds` worlds) and once as `torchrun --standalone --nproc_per_node=N` with the worlds
and the slot-step budget split evenly over the N ranks, so both runs collect the same rollout
per update and the same total. DDP averages the ranks' gradients, so an update of the N ranks
learns from the same batch as the single process's. With `--weak` every rank keeps all the
worlds instead (the budget is still split): an update of N ranks learns from N times the batch,
and each rank's update is as large as the single process's. Reported per mode: the median over rounds of
the median `charts/sps` (active agent-steps per second over whole updates, all ranks) after the
first `--skip` updates, the wall time of each run, and agent-steps per CPU-second (CPU time of
the run's processes from `getrusage(RUSAGE_CHILDREN)`, over the whole run, start-up included).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any


def run_once(
    mode: str, ranks: int, worlds: int, slot_steps: int, overrides: list[str], out: Path, weak: bool = False
) -> dict[str, Any]:
    """One training run; its metrics, wall time and CPU time. `weak`: every rank keeps all
    `worlds` (each update of the ranks learns from `ranks` times the single process's batch)."""
    per = ranks if mode == "ranks" else 1
    args = [
        *overrides,
        f"env.num_worlds={worlds if weak else worlds // per}",
        f"trainer.total_steps={slot_steps // per}",
        "trainer.eval_episodes=0",
        "trainer.progress_bar=false",
        "trainer.checkpoint_interval=0",
        "logger=jsonl",
        f"hydra.run.dir={out}",
    ]
    if mode == "ranks":
        cmd = [sys.executable, "-m", "torch.distributed.run", "--standalone", f"--nproc_per_node={ranks}"]
        cmd += ["-m", "selfplaydrive.cli", "train", *args]
    else:
        cmd = [sys.executable, "-m", "selfplaydrive.cli", "train", *args]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({proc.returncode}):\n{proc.stderr[-3000:]}")
    rows = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()]
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return {"rows": rows, "wall_s": wall, "cpu_s": cpu}


def summarize(run: dict[str, Any], skip: int) -> dict[str, float]:
    """Median sps after `skip` updates; agent-steps (sum of sps x update time is not logged, so
    from the active share and slot-steps of each row) per wall and CPU second of the run."""
    rows = run["rows"]
    sps = [r["charts/sps"] for r in rows[skip:] if "charts/sps" in r]
    prev, agent_steps = 0, 0.0
    for r in rows:  # rows are logged every update: slot-steps since the previous row x active share
        agent_steps += (r["step"] - prev) * r.get("charts/active_share", 0.0)
        prev = r["step"]
    return {
        "sps_median": statistics.median(sps) if sps else float("nan"),
        "wall_s": run["wall_s"],
        "agent_steps": agent_steps,
        "agent_steps_per_wall_s": agent_steps / run["wall_s"],
        "agent_steps_per_cpu_s": agent_steps / run["cpu_s"] if run["cpu_s"] else float("nan"),
    }


def main(argv: list[str] | None = None) -> int:
    fmt = argparse.RawDescriptionHelpFormatter
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=fmt)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--ranks", type=int, default=2)
    parser.add_argument("--worlds", type=int, default=4, help="worlds in all (split over the ranks)")
    parser.add_argument("--slot-steps", type=int, default=600_000, help="budget of each run, in all")
    parser.add_argument("--skip", type=int, default=2, help="updates left out of the sps median")
    parser.add_argument(
        "--weak",
        action="store_true",
        help="every rank keeps all --worlds (N times the batch per update; the budget is still split)",
    )
    parser.add_argument("--json", action="store_true")
    parser.add_argument("overrides", nargs="*")
    args = parser.parse_args(argv)
    if args.worlds % args.ranks and not args.weak:
        parser.error(f"--worlds {args.worlds} is not a multiple of --ranks {args.ranks}")
    results: dict[str, list[dict[str, float]]] = {"single": [], "ranks": []}
    with tempfile.TemporaryDirectory(prefix="bench_ddp_") as tmp:
        for i in range(args.rounds):
            order = ("single", "ranks") if i % 2 == 0 else ("ranks", "single")
            for mode in order:
                out = Path(tmp) / f"{mode}_{i}"
                run = run_once(mode, args.ranks, args.worlds, args.slot_steps, args.overrides, out, args.weak)
                res = summarize(run, args.skip)
                res["load_1min"] = os.getloadavg()[0]
                results[mode].append(res)
                print(f"round {i} {mode}: {json.dumps(res)}", file=sys.stderr, flush=True)
    med = {m: {k: statistics.median(r[k] for r in rs) for k in rs[0]} for m, rs in results.items()}
    pairs = zip(results["single"], results["ranks"], strict=True)
    ratios = [r["sps_median"] / s["sps_median"] for s, r in pairs]
    report = {
        "command": "python benchmarks/bench_ddp.py " + " ".join(argv if argv is not None else sys.argv[1:]),
        "ranks": args.ranks,
        "weak": args.weak,
        "median": med,
        "ratio_of_medians": med["ranks"]["sps_median"] / med["single"]["sps_median"],
        "median_round_ratio": statistics.median(ratios),
        "rounds": results,
    }
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        for mode, m in med.items():
            print(
                f"{mode:6s}: {m['sps_median']:8.0f} agent-steps/s (median of update medians), "
                f"{m['agent_steps_per_wall_s']:8.0f} per wall-s and "
                f"{m['agent_steps_per_cpu_s']:8.0f} per CPU-s over whole runs ({m['wall_s']:.0f} s)"
            )
        ratio, per_round = report["ratio_of_medians"], report["median_round_ratio"]
        print(f"ranks / single: {ratio:.2f}x (median round ratio {per_round:.2f}x)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
