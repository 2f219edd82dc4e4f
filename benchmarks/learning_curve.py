"""A training run's learning curve from its `metrics.jsonl` (logger=jsonl): wall time to the
first logged update at which the recent waypoint completion (the progress bar's figure: the
last 32 world-episodes, training coefficients) reached each threshold, and the curve sampled
at a few points.

    python benchmarks/learning_curve.py RUN_DIR/metrics.jsonl [--thresholds 0.5 0.6 0.7 0.8]

A run resumed from a checkpoint (`resume=`, e.g. continued on a later GPU lease:
`benchmarks/gpu_session.sh long`) appends to the same file, with the pause between the two
processes in its `time` column. Minutes here are training minutes: where two logged updates lie
more than `PAUSE_S` seconds further apart than the later one's own slot-steps take at its
logged rate, that rate's time is counted instead of the clock's (the pause, the new process's
start-up and the updates a killed process logged after its last checkpoint, which the resumed
run repeats and drops, are left out).
"""

from __future__ import annotations

import argparse
import json
from itertools import pairwise
from pathlib import Path

KEYS = ("recent/waypoint_completion", "recent/collision_rate", "recent/offroad_rate")
PAUSE_S = 60.0  # [s] beyond an update's own time: another process took over (a resume)


def read(path: Path) -> list[dict[str, float]]:
    """The complete JSON lines of `path` that carry the recent completion."""
    rows = []
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            row = json.loads(line)
        except json.JSONDecodeError:
            continue  # a half-written last line of a killed run
        if KEYS[0] in row:
            rows.append(row)
    return rows


def own_seconds(row: dict[str, float], steps: float) -> float:
    """Seconds `steps` slot-steps take at `row`'s logged rate."""
    return steps / max(row.get("charts/slot_sps", 1.0), 1.0)


def training_seconds(rows: list[dict[str, float]]) -> list[float]:
    """Seconds of training up to each row: from the run's start (the first row's time less its
    slot-steps' own time), with pauses between processes left out (`PAUSE_S`, module doc)."""
    elapsed = [own_seconds(rows[0], rows[0]["step"])]
    for prev, row in pairwise(rows):
        own = own_seconds(row, row["step"] - prev["step"])
        clock = row["time"] - prev["time"]
        elapsed.append(elapsed[-1] + (own if clock > own + PAUSE_S else clock))
    return elapsed


def summary(rows: list[dict[str, float]], thresholds: list[float], points: int = 8) -> list[str]:
    """Lines: minutes and slot-steps to each threshold, then the curve at `points` times."""
    if not rows:
        return ["no update with a finished world-episode was logged"]
    minutes = [t / 60 for t in training_seconds(rows)]
    lines = []
    for th in thresholds:
        hit = next((i for i, r in enumerate(rows) if r[KEYS[0]] >= th), None)
        where = "not reached" if hit is None else f"{minutes[hit]:.2f} min, {rows[hit]['step']:,} slot-steps"
        lines.append(f"completion >= {th:.0%}: {where}")
    best = max(range(len(rows)), key=lambda i: rows[i][KEYS[0]])
    lines.append(f"best: {rows[best][KEYS[0]]:.1%} at {minutes[best]:.2f} min")
    lines.append("minutes  slot-steps  completion  collision  road-edge  slot-steps/s")
    for i in sorted({round(k * (len(rows) - 1) / (points - 1)) for k in range(points)}):
        r = rows[i]
        lines.append(
            f"{minutes[i]:7.2f}  {r['step']:10,}  {r[KEYS[0]]:10.1%}  {r[KEYS[1]]:9.3f}  "
            f"{r[KEYS[2]]:9.3f}  {r.get('charts/slot_sps', float('nan')):12,.0f}"
        )
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("metrics", type=Path, help="a run's metrics.jsonl")
    parser.add_argument("--thresholds", type=float, nargs="*", default=[0.5, 0.6, 0.7, 0.8])
    args = parser.parse_args()
    print(f"{args.metrics}:")
    print("\n".join(summary(read(args.metrics), args.thresholds)))


if __name__ == "__main__":
    main()
