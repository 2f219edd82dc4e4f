"""Example 05: an ablation study as an experiment file, and how to read its per-term logs.

The study is selfplaydrive/conf/experiment/ablate_collision.yaml: the collision coefficient
C_collision drawn from U(0.5, 1) against the default U(0, 1), over three seeds. The file
carries its own sweep (`hydra.sweeper.params`), so the whole study is one command:

    selfplaydrive train -m experiment=ablate_collision

This script runs it (--tiny: seed 0 only, a few seconds per run), then reads every run's
TensorBoard event files with tensorboard's `EventAccumulator` and prints, side by side, the
per-term reward scalars the trainer writes: `term/<name>` is the mean per-agent episode sum of
each reward term (paper section 2.3) over the episodes that ended in an update, next to
`charts/collision_rate`, `charts/offroad_rate` and `charts/waypoint_completion`
(trainers/ppo/episodes.py defines them; docs/training.md "Reading the logs").

Without --tiny it runs the study as the file defines it (6 runs of 20M slot-steps: hours on a
laptop CPU; --steps sets a smaller budget per run, --out keeps the folders).

Run: python examples/05_ablation.py [--tiny] [--out FOLDER] [--steps N]
"""

from __future__ import annotations

import argparse
import json
import math
import tempfile
from pathlib import Path

from _tiny import TINY_OVERRIDES, is_tiny, run, selfplaydrive_command

TERMS = ("waypoint", "collision", "offroad", "red_light", "comfort", "center", "align", "velocity")
CHARTS = ("collision_rate", "offroad_rate", "waypoint_completion", "return_mean")


def launch(out: Path, tiny: bool, steps: int | None) -> None:
    """Run the experiment's sweep into `out` (--tiny: seed 0 only, tiny runs)."""
    fixed = [*TINY_OVERRIDES, "seed=0"] if tiny else []
    if steps is not None:
        fixed.append(f"trainer.total_steps={steps}")
    run(
        [
            *selfplaydrive_command(),
            "train",
            "-m",
            "experiment=ablate_collision",
            *fixed,
            f"hydra.sweep.dir={out}",
        ]
    )


def read_scalars(run_dir: Path) -> dict[str, float]:
    """Mean over the logged updates of every `term/*` and `charts/*` scalar of one run."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    acc = EventAccumulator(str(run_dir / "tb"), size_guidance={"scalars": 0})  # 0: keep every point
    acc.Reload()
    out = {}
    for tag in acc.Tags()["scalars"]:
        values = [e.value for e in acc.Scalars(tag)]
        out[tag] = sum(values) / len(values)
    return out


def arm(run_dir: Path) -> str:
    """'C_coll~U(low,high) seed s' from the run's resolved config and metadata."""
    import yaml

    cfg = yaml.safe_load((run_dir / "resolved_config.yaml").read_text())
    meta = json.loads((run_dir / "run_meta.json").read_text())
    c = cfg["reward"]["collision"]
    return f"U({c['low']:g},{c['high']:g}) s{meta['seed']}"


def table(runs: list[Path]) -> None:
    """Print the per-term scalars of all runs side by side (one column per run)."""
    scalars = [read_scalars(r) for r in runs]
    heads = [arm(r) for r in runs]
    width = max(14, *(len(h) + 1 for h in heads))
    print(f"{'tag':28s}" + "".join(f"{h:>{width}s}" for h in heads))
    rows = [f"term/{t}" for t in TERMS] + [f"charts/{c}" for c in CHARTS]
    for tag in rows:
        cells = [s.get(tag, math.nan) for s in scalars]
        print(f"{tag:28s}" + "".join(f"{v:>{width}.4f}" for v in cells))
    missing = [h for h, s in zip(heads, scalars, strict=True) if "term/collision" not in s]
    if missing:
        print(f"(no episode ended during training in: {', '.join(missing)}; term/* needs a finished episode)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tiny", action="store_true", help="a few seconds per run (CI)")
    parser.add_argument("--out", type=Path, default=None, help="sweep folder (default: a temporary one)")
    parser.add_argument(
        "--steps", type=int, default=None, help="trainer.total_steps per run (default: the experiment's 20M)"
    )
    args = parser.parse_args()
    tiny = is_tiny(args.tiny)
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or Path(tmp) / "ablate_collision"
        launch(out, tiny, args.steps)
        runs = sorted(
            (p for p in out.iterdir() if (p / "tb").is_dir()), key=lambda p: int(p.name.split("_")[0])
        )
        print(f"\nablation: {len(runs)} runs, per-term reward scalars (mean over the logged updates)")
        table(runs)


if __name__ == "__main__":
    main()
