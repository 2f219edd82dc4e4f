"""Example 04: a Hydra sweep from the command line over a reward and a physics setting.

The command it runs (the full version; --tiny keeps seed=0 only and shrinks every run):

    selfplaydrive train -m reward.collision.high=0.5,1.0 physics=bicycle,friction seed=0,1 \\
        trainer.total_steps=... env.num_worlds=1 trainer.rollout_length=16 \\
        trainer.eval_episodes=0 trainer.progress_bar=false hydra.sweep.dir=<folder>

`-m` runs the Cartesian product of the comma-separated values, one run folder per
combination, numbered 0, 1, ... under hydra.sweep.dir. Each folder holds
resolved_config.yaml (the full config after interpolation), run_meta.json (git commit, seed,
overrides, the chosen config options, the command line), the trainer's config.json,
run_info.json, tb/ (TensorBoard) and checkpoints/. Running the sweep in parallel: see
docs/interfaces/hydra.md (joblib launcher, submitit on SLURM).

Run: python examples/04_hydra_sweep.py [--tiny] [--out FOLDER]
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import yaml
from _tiny import TINY_OVERRIDES, is_tiny, run, selfplaydrive_command

SWEEP = ("reward.collision.high=0.5,1.0", "physics=bicycle,friction")


def sweep(out: Path, tiny: bool) -> None:
    """Launch the sweep into `out`."""
    if tiny:
        fixed = [*TINY_OVERRIDES, "seed=0"]
    else:
        fixed = [
            "trainer.total_steps=4096",
            "env.num_worlds=1",
            "trainer.rollout_length=16",
            "trainer.eval_episodes=0",
            "trainer.progress_bar=false",
            "map=procedural",  # a small town and 8 agents keep each run under a minute
            "map.size=400",
            "map.num_roundabouts=0",
            "spawner.num_agents=8",
            "spawner.min_region_lane_length=300",
            "seed=0,1",
        ]
    args = [*selfplaydrive_command(), "train", "-m", *SWEEP, *fixed]
    run(
        [
            *args,
            f"hydra.sweep.dir={out}",
        ]
    )


def describe(out: Path) -> int:
    """Print every run folder: its files, the seed, commit and swept values; return the count."""
    runs = sorted(
        (p for p in out.iterdir() if (p / "run_meta.json").is_file()), key=lambda p: int(p.name.split("_")[0])
    )
    print(f"\n{len(runs)} run folders in {out} (multirun.yaml holds the sweep's own config):")
    for folder in runs:
        meta = json.loads((folder / "run_meta.json").read_text())
        cfg = yaml.safe_load((folder / "resolved_config.yaml").read_text())
        physics = cfg["physics"]["model"]["_target_"].rsplit(".", 1)[1]
        print(f"- {folder.name}")
        print(f"    files: {', '.join(sorted(p.name for p in folder.iterdir()))}")
        print(
            f"    seed {meta['seed']}, git {meta['git_commit'][:10]}, physics {physics}, "
            f"C_collision ~ U({cfg['reward']['collision']['low']}, {cfg['reward']['collision']['high']})"
        )
    return len(runs)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tiny", action="store_true", help="a few seconds per run (CI)")
    parser.add_argument("--out", type=Path, default=None, help="sweep folder (default: a temporary one)")
    args = parser.parse_args()
    tiny = is_tiny(args.tiny)
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or Path(tmp) / "sweep"
        sweep(out, tiny)
        count = describe(out)
    expected = 4 if tiny else 8
    if count != expected:
        raise SystemExit(f"expected {expected} run folders, found {count}")
    print(f"sweep done: {count} runs")


if __name__ == "__main__":
    main()
