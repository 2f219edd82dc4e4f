"""Sweeps run on Hydra's own launchers (docs/training.md, "Sweeps and clusters"): the joblib
launcher runs the jobs of `-m` in parallel local processes, each in its own numbered folder."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("hydra_plugins.hydra_joblib_launcher", reason="needs selfplaydrive[sweep]")


def test_bench_sweep_on_the_joblib_launcher(tmp_path: Path) -> None:
    argv = [
        "bench", "-m", "hydra/launcher=joblib", "hydra.launcher.n_jobs=2", "seed=3,4",
        "threads=[1]", "steps=3", "warmup=1", "repeats=1", "stages=false", "env.num_worlds=1",
        "spawner.num_agents=8", f"hydra.sweep.dir={tmp_path}",
    ]  # fmt: skip
    code = "import sys; from selfplaydrive.cli import main; raise SystemExit(main(sys.argv[1:]))"
    run = subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "Joblib.Parallel" in run.stdout + run.stderr  # the launcher, not Hydra's basic one, ran
    seeds = []
    for job in (0, 1):
        meta = json.loads((tmp_path / str(job) / "run_meta.json").read_text())
        bench = json.loads((tmp_path / str(job) / "bench.json").read_text())
        seeds.append(meta["seed"])
        assert bench["num_agents"] == 8 and len(bench["results"]) == 1
    assert sorted(seeds) == [3, 4]
