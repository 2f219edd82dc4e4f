"""Compare candidate policies before one is shipped (issue #16 item 3; docs/training.md, "The
pretrained policy"): greedy 32-agent waypoint completion on sets of validation worlds, each
candidate's difference from the first one paired set by set, and optionally the turn-lane suite.

    python benchmarks/select_candidates.py selfplaydrive/pretrained/main_job.pt runs/x/checkpoints/final.pt
    python benchmarks/select_candidates.py pretrained runs/x/checkpoints/final.pt --turn-lanes 0 1
    python benchmarks/select_candidates.py pretrained runs/x/checkpoints/final.pt --seeds 29 100 \
        --json out.json

Each set of worlds is `pretrained_report.completion_eval` with the run's seed replaced: the
shipped run's env under the paper's evaluation protocol (fixed evaluation coefficients, the
training curricula off), 32 world-episodes. Every candidate drives the same worlds, so the
per-set differences from the first candidate (the baseline, usually the shipped policy) cancel
most of the 2-5 points by which one set moves a policy's completion; their mean gets a Student-t
interval over the sets. The report's held-out seeds (`pretrained_report.SET_SEEDS`) are refused:
a policy picked on them would make the report's mean a biased estimate (session 31 showed four
validation sets picking a policy that was no better on eight others).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import pretrained_report  # a sibling script, not a package

# Validation worlds: the shipped b3's own seed (29) and seven round seeds; none of them is in
# pretrained_report.SET_SEEDS.
VALIDATION_SEEDS = (29, 100, 200, 300, 400, 500, 600, 700)


def check_seeds(seeds: list[int]) -> list[int]:
    """The validation seeds, refusing the report's held-out ones and repeats."""
    held = sorted(set(seeds) & set(pretrained_report.SET_SEEDS))
    if held:
        raise ValueError(
            f"--seeds {held} are the report's held-out sets (pretrained_report.SET_SEEDS "
            f"{pretrained_report.SET_SEEDS[0]}-{pretrained_report.SET_SEEDS[-1]}); "
            "pick candidates on other seeds"
        )
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"--seeds repeats a seed: {seeds}")
    return list(seeds)


def resolve(candidate: str) -> Path:
    """A checkpoint path (`pretrained` names the shipped policy), checked before any candidate
    is evaluated."""
    from selfplaydrive import pretrained

    path = Path(pretrained.resolve_spec(candidate))
    if not path.is_file():
        raise FileNotFoundError(f"candidate checkpoint {candidate!r} is not a file")
    return path


def paired(values: dict[str, list[float]], baseline: str) -> dict[str, dict[str, float]]:
    """Each candidate's completion minus the baseline's, set by set: mean and Student-t interval.

    Args:
        values: Candidate name -> completion per set (the same sets, in the same order).
        baseline: The name every other candidate is compared with.

    Returns:
        Name -> {mean, lo, hi} of the per-set differences (the baseline is left out).
    """
    from selfplaydrive.eval.stats import mean_estimate

    base = np.asarray(values[baseline], dtype=np.float64)
    out = {}
    for name, vals in values.items():
        if name == baseline:
            continue
        est = mean_estimate(np.asarray(vals, dtype=np.float64) - base)
        out[name] = {"mean": est.value, "lo": est.lo, "hi": est.hi}
    return out


def turn_lanes(checkpoint: Path, seeds: list[int]) -> list[int]:
    """Correct lanes of 128 turn-lane scenarios (the paper's variant) per suite seed."""
    from turn_lane_probe import probe

    return [
        int(probe(str(checkpoint), "default", 128, 15.0, s, paper_only=True)["paper"]["correct_lane"])
        for s in seeds
    ]


def evaluate(
    candidates: list[str], seeds: list[int], episodes: int, lane_seeds: list[int], agents: int = 32
) -> dict[str, Any]:
    """Every candidate on every set of worlds (and turn-lane seed); the table's data.

    Args:
        candidates: Checkpoints (or `pretrained`); the first is the baseline.
        seeds: Validation seeds, each replacing the run's seed (one set of worlds each).
        episodes: World-episodes per set.
        lane_seeds: Seeds of the turn-lane suite (empty: skip it).
        agents: Agents per world (the paper's 32).
    """
    if len(set(candidates)) != len(candidates):
        raise ValueError(f"a candidate is named twice: {candidates}")
    rows: dict[str, Any] = {}
    for name in candidates:
        ckpt = resolve(name)
        start = time.perf_counter()
        sets = [
            pretrained_report.completion_eval("default", agents, episodes, True, ckpt, seed=s) for s in seeds
        ]
        rows[name] = {
            "completion": [float(r["waypoint_completion"]) for r in sets],
            "collision_rate": [float(r["collision_rate"]) for r in sets],
            "offroad_rate": [float(r["offroad_rate"]) for r in sets],
            "turn_lanes": turn_lanes(ckpt, lane_seeds) if lane_seeds else [],
            "wall_s": round(time.perf_counter() - start, 1),
        }
        print(f"{name}: {json.dumps(rows[name])}", file=sys.stderr, flush=True)
    diffs = paired({n: r["completion"] for n, r in rows.items()}, candidates[0])
    return {
        "seeds": seeds,
        "episodes_per_set": episodes,
        "agents_per_world": agents,
        "turn_lane_seeds": lane_seeds,
        "candidates": rows,
        "baseline": candidates[0],
        "paired": diffs,
    }


def markdown(result: dict[str, Any]) -> list[str]:
    """The comparison as a Markdown table: one row per candidate."""
    seeds = result["seeds"]
    head = (
        "| candidate | "
        + " | ".join(str(s) for s in seeds)
        + " | mean | vs baseline (95 %) | collision | turn lanes |"
    )
    lines = [head, "|" + "---|" * (len(seeds) + 5)]
    for name, row in result["candidates"].items():
        comp = row["completion"]
        diff = result["paired"].get(name)
        vs = "baseline"
        if diff is not None:
            vs = f"{100 * diff['mean']:+.1f} ({100 * diff['lo']:+.1f} to {100 * diff['hi']:+.1f})"
        lanes = " / ".join(str(x) for x in row["turn_lanes"]) or "-"
        cells = " | ".join(f"{100 * c:.1f} %" for c in comp)
        lines.append(
            f"| {name} | {cells} | {100 * float(np.mean(comp)):.1f} % | {vs} | "
            f"{float(np.mean(row['collision_rate'])):.3f} | {lanes} |"
        )
    return lines


def main(argv: list[str] | None = None) -> int:
    fmt = argparse.RawDescriptionHelpFormatter
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=fmt)
    parser.add_argument(
        "candidates", nargs="+", help="checkpoints or `pretrained`; the first is the baseline"
    )
    parser.add_argument("--seeds", type=int, nargs="+", default=list(VALIDATION_SEEDS))
    parser.add_argument("--episodes", type=int, default=32, help="world-episodes per set")
    parser.add_argument("--turn-lanes", type=int, nargs="*", default=[], help="turn-lane suite seeds")
    parser.add_argument("--json", default=None, help="also write the result here")
    args = parser.parse_args(argv)
    result = evaluate(args.candidates, check_seeds(args.seeds), args.episodes, args.turn_lanes)
    print("\n".join(markdown(result)))
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
