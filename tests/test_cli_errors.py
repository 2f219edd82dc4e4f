"""Bad input on the command line (issue #14 item 6): one line on stderr and exit code 1, no
traceback, and nothing built or written first; HYDRA_FULL_ERROR=1 keeps the traceback."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from selfplaydrive.cli import main
from selfplaydrive.errors import CheckpointError, ConfigError, MissingExtraError
from selfplaydrive.hydra_app import run_hydra


def _one_line_error(capsys, argv: list[str]) -> str:
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 1, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    assert lines[0].startswith(f"selfplaydrive {argv[0]}: error: "), err
    return lines[0]


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["train", "env.num_worlds=0"], "env.num_worlds: expected an integer >= 1, got 0"),
        (["train", "env.num_worlds=-1"], "env.num_worlds: expected an integer >= 1, got -1"),
        (["train", "env.num_worlds=abc"], "env.num_worlds: expected an integer >= 1, got 'abc'"),
        (["train", "env.num_worlds=2.5"], "env.num_worlds: expected an integer >= 1, got 2.5"),
        (["train", "env.num_threads=-3"], "env.num_threads: expected an integer in [1, "),
        (["train", "env.num_threads=40000"], "got 40000"),
        (["train", "seed=abc"], "seed: expected a non-negative integer, got 'abc'"),
        (["train", "seed=-1"], "seed: expected a non-negative integer, got -1"),
        (["train", "map=file"], "map.spec: map=file needs the map file"),
        (["bench", "steps=-1"], "steps: expected an integer >= 1, got -1"),
        (["bench", "threads=[1,0]"], "threads: expected an integer in [1, "),
        (["render", "seed=1.5"], "seed: expected a non-negative integer, got 1.5"),
        # Hydra's override grammar and OmegaConf's interpolation errors: one line too
        (["train", "seed=["], "no viable alternative at input '['"),
        (["train", "env.num_worlds=${nope}"], "env.num_worlds: Interpolation key 'nope' not found"),
    ],
)
def test_bad_values_give_one_line_before_any_run(capsys, tmp_path, argv, expected):
    run_dir = tmp_path / "run"
    line = _one_line_error(capsys, [*argv, f"hydra.run.dir={run_dir}"])
    assert expected in line
    assert not run_dir.exists()  # refused before Hydra made the run folder


def test_each_sweep_job_is_checked(capsys, tmp_path):
    # the first value of a sweep is checked up front, the others when their job starts: the
    # bad job reports one line and the exit code says a run failed
    argv = ["bench", "-m", "steps=1,-5", "warmup=0", "repeats=1", "threads=[1]", "stages=false"]
    code = main([*argv, "env.num_worlds=1", f"hydra.sweep.dir={tmp_path}"])
    err = capsys.readouterr().err
    assert code == 1 and "Traceback" not in err
    assert "selfplaydrive bench: error: steps: expected an integer >= 1, got -5" in err.splitlines()


@pytest.mark.parametrize(
    "error",
    [
        CheckpointError("policy: not a torch checkpoint file", "x.pt"),
        MissingExtraError("this feature needs the optional module 'torch'; install torch"),
        ConfigError("trainer.lr: expected a positive number, got -1"),
    ],
)
def test_task_errors_become_one_line(capsys, tmp_path, error):
    def task(cfg):
        raise error

    code = run_hydra("sim", task, [f"hydra.run.dir={tmp_path}"])
    err = capsys.readouterr().err
    assert code == 1 and err.strip() == f"selfplaydrive sim: error: {error}"


def test_full_error_keeps_the_traceback(tmp_path, monkeypatch):
    monkeypatch.setenv("HYDRA_FULL_ERROR", "1")
    with pytest.raises(ConfigError, match=r"env\.num_worlds"):
        main(["train", "env.num_worlds=0", f"hydra.run.dir={tmp_path}"])

    def task(cfg):
        raise CheckpointError("policy: truncated file", "x.pt")

    with pytest.raises(CheckpointError, match="truncated file"):
        run_hydra("sim", task, [f"hydra.run.dir={tmp_path}"])


def test_eval_missing_and_foreign_checkpoints(capsys, tmp_path):
    assert "/nonexistent.pt" in _one_line_error(
        capsys, ["eval", "policy=/nonexistent.pt", f"hydra.run.dir={tmp_path}"]
    )
    bogus = tmp_path / "notes.pt"
    bogus.write_text("not a checkpoint")
    assert str(bogus) in _one_line_error(capsys, ["eval", f"policy={bogus}", f"hydra.run.dir={tmp_path}"])


def test_train_without_torch_says_how_to_install_it(tmp_path):
    # a fresh interpreter where `import torch` fails, as on an install without it
    code = (
        "import sys; sys.modules['torch'] = None\n"
        "from selfplaydrive.cli import main\n"
        f"sys.exit(main(['train', 'hydra.run.dir={tmp_path}']))\n"
    )
    env = {**os.environ, "HYDRA_FULL_ERROR": "0"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=env)
    lines = out.stderr.strip().splitlines()
    assert out.returncode == 1 and len(lines) == 1, out.stderr
    assert lines[0].startswith("selfplaydrive train: error: ") and "pip install torch" in lines[0]
