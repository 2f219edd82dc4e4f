"""The `logger/` config group: each option writes what it should (TensorBoard events, JSON
lines, nothing), disabled ranks write nothing, and both trainers use the logger of the config."""

from __future__ import annotations

import json
import math

import pytest

from selfplaydrive.builder import compose, instantiate, valid_options
from selfplaydrive.trainers.ppo.logging import JsonlLogger, ProgressLogger, TensorBoardLogger
from selfplaydrive.trainers.run import make_logger

VALUES = [
    ({"sps": 100.0, "losses/policy": 0.5, "return_mean": math.nan, "note": "text"}, 64),
    ({"sps": 200.0, "term/collision": -1.25}, 128),
]
# a tiny env: 1 world of 6 agent slots with 2 s episodes
TINY_ENV = [
    "env.num_worlds=1",
    "spawner.num_agents=6",
    "spawner.num_static=4",
    "spawner.num_pedestrians=2",
    "spawner.episode_lengths=[2.0]",
]


def _files(root):
    return sorted(str(p.relative_to(root)) for p in root.rglob("*") if p.is_file())


def _tb_scalars(folder):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    acc = EventAccumulator(str(folder))
    acc.Reload()
    return {tag: [(e.step, e.value) for e in acc.Scalars(tag)] for tag in acc.Tags()["scalars"]}


def _jsonl(path):
    rows = [json.loads(line) for line in path.read_text().splitlines()]
    for row in rows:
        assert row.pop("time") > 0
    return rows


def _log(name, run_dir, **kwargs):
    factory = instantiate(compose("train", [f"logger={name}"]).logger)
    logger = factory(run_dir=run_dir, total_updates=2, progress_bar=False, initial=0, **kwargs)
    for values, step in VALUES:
        logger.scalars(values, step)
        logger.progress(1, values)
    logger.text("a line")
    logger.close()
    return logger


def test_logger_group_options():
    assert valid_options("logger") == ["jsonl", "none", "tensorboard"]
    assert compose("train").logger._target_.endswith("TensorBoardLogger")  # the default


def test_tensorboard_logger_writes_event_files(tmp_path, capsys):
    assert isinstance(_log("tensorboard", tmp_path, enabled=True), TensorBoardLogger)
    assert all(f.startswith("tb/events.out.tfevents.") for f in _files(tmp_path)), _files(tmp_path)
    scalars = _tb_scalars(tmp_path / "tb")
    assert scalars == {
        "charts/sps": [(64, 100.0), (128, 200.0)],
        "losses/policy": [(64, 0.5)],
        "term/collision": [(128, -1.25)],
    }  # NaN and the string are skipped, keys without a slash go under charts/
    assert "a line" in capsys.readouterr().out


def test_jsonl_logger_writes_json_lines(tmp_path):
    assert isinstance(_log("jsonl", tmp_path, enabled=True), JsonlLogger)
    assert _files(tmp_path) == ["metrics.jsonl"]
    assert _jsonl(tmp_path / "metrics.jsonl") == [
        {"step": 64, "charts/sps": 100.0, "losses/policy": 0.5},
        {"step": 128, "charts/sps": 200.0, "term/collision": -1.25},
    ]
    _log("jsonl", tmp_path, enabled=True)  # a resumed run appends
    assert len(_jsonl(tmp_path / "metrics.jsonl")) == 4


def test_none_logger_writes_no_file(tmp_path, capsys):
    logger = _log("none", tmp_path, enabled=True)
    assert type(logger) is ProgressLogger
    assert _files(tmp_path) == []
    assert "a line" in capsys.readouterr().out


@pytest.mark.parametrize("name", ["tensorboard", "jsonl", "none"])
def test_disabled_logger_writes_and_prints_nothing(name, tmp_path, capsys):
    _log(name, tmp_path, enabled=False)  # ranks other than 0
    assert _files(tmp_path) == []
    assert capsys.readouterr().out == ""


def test_progress_bar_counts_updates(tmp_path):
    logger = ProgressLogger(tmp_path, total_updates=5, progress_bar=True, initial=1)
    logger.progress(2, {"sps": 3.0})
    assert logger.bar.n == 3 and logger.bar.total == 5
    logger.close()


def test_make_logger_accepts_factory_config_or_none(tmp_path):
    assert make_logger(None) is TensorBoardLogger  # train_run's default: what training always did
    assert make_logger(JsonlLogger) is JsonlLogger
    node = {"_target_": "selfplaydrive.trainers.ppo.logging.JsonlLogger", "filename": "m.jsonl"}
    logger = make_logger(node)(run_dir=tmp_path, total_updates=1, progress_bar=False, enabled=True, initial=0)
    logger.scalars({"sps": 1.0}, 1)
    logger.close()
    assert _files(tmp_path) == ["m.jsonl"]
    with pytest.raises(TypeError, match="logger"):
        make_logger(3)


def test_train_cli_uses_the_logger_of_the_config(tmp_path):
    """`selfplaydrive train logger=jsonl`: PPO's scalars land in metrics.jsonl, no tb/."""
    from selfplaydrive.hydra_app import run_hydra, train_task

    run_dir = tmp_path / "run"
    argv = [
        "logger=jsonl",
        "trainer.total_steps=48",  # 6 slots x 4 steps x 2 updates
        "trainer.rollout_length=4",
        "trainer.num_epochs=1",
        "trainer.num_minibatches=1",
        "trainer.eval_episodes=0",
        "trainer.checkpoint_interval=0",
        "trainer.progress_bar=false",
        "trainer.device=cpu",
        "model.input_size=8",
        "model.hidden_size=16",
        "model.lstm_size=16",
        *TINY_ENV,
        f"hydra.run.dir={run_dir}",
    ]
    assert run_hydra("train", train_task, argv) == 0
    assert not (run_dir / "tb").exists()
    rows = _jsonl(run_dir / "metrics.jsonl")
    assert [r["step"] for r in rows] == [24, 48]
    assert all(
        {"charts/sps", "losses/policy", "losses/value", "charts/learning_rate"} <= set(r) for r in rows
    )


@pytest.mark.parametrize("name", ["jsonl", "none"])
def test_sb3_trainer_uses_the_logger_of_the_config(name, tmp_path):
    from selfplaydrive.hydra_app import run_hydra, train_task

    run_dir = tmp_path / "run"
    argv = [
        "trainer=sb3",
        f"logger={name}",
        "trainer.total_timesteps=96",
        "trainer.n_steps=8",
        "trainer.batch_size=24",
        "trainer.n_epochs=1",
        "trainer.eval_episodes=0",
        "trainer.embed_size=8",
        "trainer.features_dim=16",
        "trainer.net_arch=[16]",
        "trainer.device=cpu",
        *TINY_ENV,
        f"hydra.run.dir={run_dir}",
    ]
    assert run_hydra("train", train_task, argv) == 0
    assert not (run_dir / "tb").exists()
    if name == "none":
        assert not (run_dir / "metrics.jsonl").exists()
        return
    rows = _jsonl(run_dir / "metrics.jsonl")
    assert [r["step"] for r in rows] == [48, 96]  # one line per rollout of 8 steps x 6 slots
    assert all("time/fps" in r for r in rows)
    assert "train/value_loss" in rows[-1]  # SB3 logs the losses of an update with the next rollout
