"""A training run's learning curve from its `metrics.jsonl` (logger=jsonl): wall time to the
first logged update at which the recent waypoint completion (the progress bar's figure: the
last 32 world-episodes, training coefficients) reached each threshold, and the curve sampled
at a few points.

    python benchmarks/learning_curve.py RUN_DIR/metrics.jsonl [--thresholds 0.5 0.6 0.7 0.8]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

KEYS = ("recent/waypoint_completion", "recent/collision_rate", "recent/offroad_rate")


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


def summary(rows: list[dict[str, float]], thresholds: list[float], points: int = 8) -> list[str]:
    """Lines: minutes and slot-steps to each threshold, then the curve at `points` times."""
    if not rows:
        return ["no update with a finished world-episode was logged"]
    t0 = rows[0]["time"] - rows[0]["step"] / max(rows[0].get("charts/slot_sps", 1.0), 1.0)
    lines = []
    for th in thresholds:
        hit = next((r for r in rows if r[KEYS[0]] >= th), None)
        where = f"{(hit['time'] - t0) / 60:.2f} min, {hit['step']:,} slot-steps" if hit else "not reached"
        lines.append(f"completion >= {th:.0%}: {where}")
    best = max(rows, key=lambda r: r[KEYS[0]])
    lines.append(f"best: {best[KEYS[0]]:.1%} at {(best['time'] - t0) / 60:.2f} min")
    lines.append("minutes  slot-steps  completion  collision  road-edge  slot-steps/s")
    for i in sorted({round(k * (len(rows) - 1) / (points - 1)) for k in range(points)}):
        r = rows[i]
        lines.append(
            f"{(r['time'] - t0) / 60:7.2f}  {r['step']:10,}  {r[KEYS[0]]:10.1%}  {r[KEYS[1]]:9.3f}  "
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
