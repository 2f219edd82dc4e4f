"""Settings of the main job compared over several seeds: train each (setting, seed) pair with
`selfplaydrive train`, then table every run's learning curve and final evaluation, each
setting's means, and its paired difference to the first setting (docs/training.md, "Tuning the
main job": one run says little, the evaluation alone moves completion by about five points).

    python benchmarks/seed_trials.py --out runs/trials --seeds 0 1 2 3 --parallel 2 \\
        --setting "default:" --setting "center4:reward.terms.center=4"
    python benchmarks/seed_trials.py --out runs/trials --seeds 0 1 2 3 \\
        --setting "default:" --setting "center4:reward.terms.center=4" --table-only

A setting is `NAME:OVERRIDES` (Hydra overrides of `selfplaydrive train`, space-separated; none
for the defaults). Run folders are `OUT/NAME_sSEED` with the log beside them (`.log`); a pair
whose folder already holds `eval.json` is not trained again, so an interrupted comparison
continues where it stopped. The final evaluation is the one under the paper's protocol (the fixed
evaluation coefficients): `eval.json` itself when the run trained at them (`reward=eval`, the
main job's default), else its `fixed_eval_coefficients` entry. The curve columns are the
progress bar's figures (the last 32 world-episodes) when the run passed 1M, 2M, 3M and 4M
agent-steps: completion % / collision rate / road-edge rate.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

TARGET = {"waypoint_completion": 0.50, "collision_rate": 0.20}  # issue #16 item 2, the main job
CURVE_POINTS = (1e6, 2e6, 3e6, 4e6)  # agent-steps
_NAME = re.compile(r"^[A-Za-z0-9_-]+$")
_CLI = "import sys; from selfplaydrive.cli import main; sys.exit(main(sys.argv[1:]))"


@dataclass(frozen=True)
class Setting:
    """One configuration to compare: a folder-safe name and its Hydra overrides."""

    name: str
    overrides: tuple[str, ...] = field(default_factory=tuple)


def parse_setting(text: str) -> Setting:
    """`NAME:OVERRIDES` -> Setting; raises ValueError naming the text and the expected form."""
    name, sep, rest = text.partition(":")
    if not sep or not _NAME.match(name):
        raise ValueError(
            f"--setting {text!r}: expected NAME:OVERRIDES with NAME of letters, digits, '_' or '-' "
            "(e.g. 'center4:reward.terms.center=4', or 'default:' for no overrides)"
        )
    return Setting(name, tuple(rest.split()))


def run_dir(out: Path, setting: Setting, seed: int) -> Path:
    return out / f"{setting.name}_s{seed}"


def train_argv(out: Path, setting: Setting, seed: int) -> list[str]:
    """The `selfplaydrive train` command of one pair, run by this interpreter."""
    return [
        sys.executable, "-c", _CLI, "train", f"seed={seed}", "logger=jsonl",
        "trainer.progress_bar=false", f"hydra.run.dir={run_dir(out, setting, seed)}", *setting.overrides,
    ]  # fmt: skip


def train_all(out: Path, settings: list[Setting], seeds: list[int], parallel: int) -> dict[str, int]:
    """Train the pairs without an `eval.json`, at most `parallel` at a time, in seed-major order
    (every setting's seed 0 first), so an early look already compares like with like. Prints a
    line per finished run and returns each run folder's name with its exit code."""
    todo = [
        (s, seed) for seed in seeds for s in settings if not (run_dir(out, s, seed) / "eval.json").is_file()
    ]
    running: list[tuple[subprocess.Popen, Path, float, Any]] = []
    done: dict[str, int] = {}
    while todo or running:
        while todo and len(running) < parallel:
            setting, seed = todo.pop(0)
            folder = run_dir(out, setting, seed)
            folder.parent.mkdir(parents=True, exist_ok=True)
            log = open(folder.with_suffix(".log"), "w", encoding="utf-8")  # closed when the run ends
            proc = subprocess.Popen(train_argv(out, setting, seed), stdout=log, stderr=subprocess.STDOUT)
            running.append((proc, folder, time.monotonic(), log))
        time.sleep(0.5)
        for item in [r for r in running if r[0].poll() is not None]:
            proc, folder, start, log = item
            log.close()
            running.remove(item)
            minutes = (time.monotonic() - start) / 60
            print(f"{folder.name}: exit {proc.returncode}, {minutes:.1f} min", file=sys.stderr, flush=True)
            done[folder.name] = proc.returncode
    return done


def curve(metrics: Path) -> tuple[list[dict[str, float] | None], dict[str, float] | None, float]:
    """The progress bar's figures at each of CURVE_POINTS agent-steps (None where the run did
    not get there), the last logged ones, and the run's agent-steps (slot-steps times the share
    of slots that acted, summed over the updates)."""
    agent, prev, last = 0.0, 0, None
    cells: list[dict[str, float] | None] = [None] * len(CURVE_POINTS)
    for line in metrics.read_text(encoding="utf-8").splitlines() if metrics.is_file() else []:
        try:
            row = json.loads(line)
        except json.JSONDecodeError:
            continue  # a half-written last line of a running or killed run
        agent += row.get("charts/active_share", 0.0) * (row["step"] - prev)
        prev = row["step"]
        if "recent/waypoint_completion" not in row:
            continue
        last = row
        for i, point in enumerate(CURVE_POINTS):
            if cells[i] is None and agent >= point:
                cells[i] = row
    return cells, last, agent


def final_eval(folder: Path) -> dict[str, Any] | None:
    """The run's evaluation under the paper's protocol, or None before the run has one (or when
    it has one without figures)."""
    path = folder / "eval.json"
    if not path.is_file():
        return None
    summary = json.loads(path.read_text(encoding="utf-8"))
    summary = summary.get("fixed_eval_coefficients", summary)
    # an evaluation cut off by eval_max_steps before any world-episode ended has no rates
    return summary if "waypoint_completion" in summary else None


def _cell(row: dict[str, float] | None) -> str:
    if row is None:
        return "-"
    return (
        f"{100 * row['recent/waypoint_completion']:.1f} / {row['recent/collision_rate']:.2f} / "
        f"{row['recent/offroad_rate']:.2f}"
    )


def mean_se(values: list[float]) -> tuple[float, float]:
    """Mean and its standard error (nan with fewer than two values)."""
    if not values:
        return math.nan, math.nan
    if len(values) < 2:
        return values[0], math.nan
    return statistics.fmean(values), statistics.stdev(values) / math.sqrt(len(values))


def tables(out: Path, settings: list[Setting], seeds: list[int]) -> str:
    """Markdown: a row per run, then a row per setting with its means against the first setting."""
    lines = [
        "| setting | seed | 1M | 2M | 3M | 4M | end (agent-steps) | completion % / collision rate |",
        "|---|---|---|---|---|---|---|---|",
    ]
    finals: dict[str, dict[int, dict[str, Any]]] = {}
    for s in settings:
        finals[s.name] = {}
        for seed in seeds:
            folder = run_dir(out, s, seed)
            cells, last, agent = curve(folder / "metrics.jsonl")
            ev = final_eval(folder)
            if ev is not None:
                finals[s.name][seed] = ev
            shown = f"{100 * ev['waypoint_completion']:.1f} / {ev['collision_rate']:.3f}" if ev else "-"
            end = f"{_cell(last)} ({agent / 1e6:.2f}M)" if last else "-"
            lines.append(f"| {s.name} | {seed} | " + " | ".join(map(_cell, cells)) + f" | {end} | {shown} |")
    lines += [
        "",
        "Means over the seeds with an evaluation; target: completion >= "
        f"{TARGET['waypoint_completion']:.0%}, collision rate <= {TARGET['collision_rate']}; the "
        "difference is paired by seed against "
        f"`{settings[0].name}` (mean +- standard error).",
        "",
        "| setting | seeds | completion % | collision rate | seeds meeting both | completion diff "
        "| collision diff |",
        "|---|---|---|---|---|---|---|",
    ]
    base = finals[settings[0].name]
    for s in settings:
        ev = finals[s.name]
        comp = [100 * e["waypoint_completion"] for e in ev.values()]
        coll = [e["collision_rate"] for e in ev.values()]
        both = sum(
            e["waypoint_completion"] >= TARGET["waypoint_completion"]
            and e["collision_rate"] <= TARGET["collision_rate"]
            for e in ev.values()
        )
        paired = [k for k in ev if k in base]
        dc = mean_se([100 * (ev[k]["waypoint_completion"] - base[k]["waypoint_completion"]) for k in paired])
        dr = mean_se([ev[k]["collision_rate"] - base[k]["collision_rate"] for k in paired])
        lines.append(
            f"| {s.name} | {len(ev)} | {mean_se(comp)[0]:.1f} | {mean_se(coll)[0]:.3f} | {both}/{len(ev)} "
            f"| {dc[0]:+.1f} +- {dc[1]:.1f} | {dr[0]:+.3f} +- {dr[1]:.3f} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", required=True, help="folder of the run folders")
    parser.add_argument(
        "--setting", action="append", required=True, help="NAME:OVERRIDES; the first is the baseline"
    )
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3])
    parser.add_argument("--parallel", type=int, default=1, help="runs at a time")
    parser.add_argument("--table-only", action="store_true", help="table the runs that exist; train nothing")
    args = parser.parse_args(argv)
    try:
        settings = [parse_setting(t) for t in args.setting]
    except ValueError as exc:
        parser.error(str(exc))
    names = [s.name for s in settings]
    if len(set(names)) != len(names):
        parser.error(f"--setting: names repeat in {names}")
    if args.parallel < 1:
        parser.error(f"--parallel {args.parallel}: expected an integer >= 1")
    out = Path(args.out)
    failed = []
    if not args.table_only:
        failed = [name for name, code in train_all(out, settings, args.seeds, args.parallel).items() if code]
    print(tables(out, settings, args.seeds))
    if failed:
        print(
            f"{len(failed)} run(s) failed, their logs (NAME.log) are beside the run folders:",
            *failed,
            sep="\n",
            file=sys.stderr,
        )
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
