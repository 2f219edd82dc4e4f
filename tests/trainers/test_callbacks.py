"""Trainer callbacks: the hooks run where the contract says, returned scalars are logged, bad
entries are refused by index, DiversityCallback records only the last part of training,
writes the section 5.4 data and survives a resume exactly, and WeightAveraging ends a run
with the mean of its last weights."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from ppo_helpers import TinyPolicy, lane_env, resume_trainer

from selfplaydrive.builder import compose, instantiate
from selfplaydrive.errors import ConfigError
from selfplaydrive.trainers import PPOConfig, PPOTrainer
from selfplaydrive.trainers.callbacks import (
    DiversityCallback,
    TermWeightSchedule,
    WeightAveraging,
    build_callbacks,
)

T = 6  # rollout_length
CFG = dict(
    total_steps=5 * T * 12,  # 5 updates of 3 worlds x 4 slots
    rollout_length=T,
    num_minibatches=2,
    num_epochs=1,
    device="cpu",
    progress_bar=False,
    checkpoint_interval=0,
    torch_threads=1,
)


class Recorder:
    def __init__(self) -> None:
        self.calls: list[tuple[str, int]] = []

    def on_start(self, trainer) -> None:
        self.calls.append(("start", trainer.update_idx))

    def on_rollout(self, trainer) -> None:
        self.calls.append(("rollout", trainer.update_idx))

    def on_step(self, trainer) -> None:
        self.calls.append(("step", trainer.update_idx))

    def on_update(self, trainer, metrics) -> dict[str, float]:
        self.calls.append(("update", trainer.update_idx))
        return {"custom/update": float(trainer.update_idx)}

    def on_end(self, trainer, metrics) -> None:
        self.calls.append(("end", trainer.update_idx))


class ListLogger:
    def __init__(self) -> None:
        self.rows: list[dict[str, float]] = []

    def scalars(self, values, step) -> None:
        self.rows.append(dict(values))

    def progress(self, updates, values) -> None:
        pass


def make_trainer(callbacks, run_dir=None, **cfg) -> PPOTrainer:
    torch.manual_seed(0)
    env = lane_env(num_worlds=3, episode_length=1.5)
    model = TinyPolicy(env.layout.obs_dim, env.action_space.nvec)
    return PPOTrainer(env, model, PPOConfig(**dict(CFG, callbacks=callbacks, **cfg)), run_dir)


def test_hooks_run_in_order_and_returned_scalars_are_logged():
    cb, logger = Recorder(), ListLogger()
    trainer = make_trainer([cb])
    trainer.train(3, logger=logger)
    trainer.train(logger=logger)  # on to total_updates = 5: on_end once, at the end
    kinds = [k for k, _ in cb.calls]
    assert kinds.count("start") == 2 and kinds.count("end") == 1 and kinds[-1] == "end"
    assert kinds.count("step") == 5 * T and kinds.count("update") == 5
    assert [u for k, u in cb.calls if k == "rollout"] == [0, 1, 2, 3, 4]  # before each rollout
    assert kinds[kinds.index("rollout") + 1] == "step"
    assert [u for k, u in cb.calls if k == "update"] == [1, 2, 3, 4, 5]
    assert [row["custom/update"] for row in logger.rows] == [1.0, 2.0, 3.0, 4.0, 5.0]
    trainer.evaluate(1, 20, False, seed=9)  # the evaluation's steps are not training steps
    assert [k for k, _ in cb.calls].count("step") == 5 * T
    assert trainer.config.to_dict()["callbacks"] == [f"{__name__}.Recorder"]


def test_bad_callback_entries_are_refused_by_index():
    with pytest.raises(ConfigError, match=r"trainer.callbacks\[1\] = .*expected an object with at least one"):
        build_callbacks([Recorder(), object()])
    with pytest.raises(ConfigError, match=r"trainer.callbacks\[0\] = \{'fraction': 0.5\}: expected a node"):
        build_callbacks([{"fraction": 0.5}])
    with pytest.raises(ConfigError, match=r"DiversityCallback.fraction = 0: expected a number in \(0, 1\]"):
        DiversityCallback(fraction=0)


def test_callbacks_from_the_trainer_config():
    target = "selfplaydrive.trainers.callbacks.DiversityCallback"
    cfg = compose("train", [f"trainer.callbacks=[{{_target_: {target}, fraction: 0.5}}]"])
    config = instantiate(cfg.trainer)
    assert isinstance(config.callbacks[0], DiversityCallback) and config.callbacks[0].fraction == 0.5


def test_diversity_callback_records_the_last_tenth_and_writes_the_analysis(tmp_path):
    cb = DiversityCallback(fraction=0.2, lateral_every=1, exposure_every=1)
    trainer = make_trainer([cb], tmp_path, total_steps=10 * T * 12)  # 10 updates: the last 2
    assert cb.first_update(10) == 8
    trainer.train(8)
    assert cb.log() is None  # nothing before the window
    trainer.train()
    log = cb.log()
    assert cb.recorder._steps == 2 * T
    assert log.offroad_exposure.sum() > 0 and len(log.lat_bias) > 0
    data = json.loads((tmp_path / "diversity" / "diversity.json").read_text())
    assert data["offroad"]["exposure"] == pytest.approx(list(log.offroad_exposure))
    assert (tmp_path / "diversity" / "lateral_vs_bias.png").is_file()


def test_diversity_state_survives_a_resume_exactly(tmp_path):
    a_cb = DiversityCallback(fraction=0.5, lateral_every=1, exposure_every=1)
    a = make_trainer([a_cb], None, total_steps=6 * T * 12)  # window: updates 3, 4, 5
    a.train(4)
    a.save(tmp_path / "mid.pt")
    a.train()
    b_cb = DiversityCallback(fraction=0.5, lateral_every=1, exposure_every=1)
    b = make_trainer([b_cb], None, total_steps=6 * T * 12)
    b.load(tmp_path / "mid.pt")
    b.train()
    la, lb = a_cb.log(), b_cb.log()
    for name in ("offroad_c", "coll_self", "lat_bias", "lat_offset", "offroad_exposure", "pair_exposure"):
        np.testing.assert_array_equal(getattr(la, name), getattr(lb, name), err_msg=name)
    assert b_cb.recorder._steps == a_cb.recorder._steps == 3 * T
    assert len(la.lat_bias) > 0


class WeightSpy:
    """Records the env's collision weight at every training step."""

    def __init__(self) -> None:
        self.weights: list[float] = []

    def on_step(self, trainer) -> None:
        self.weights.append(trainer.env.term_weight("collision"))


def test_term_weight_schedule_values_by_hand():
    schedule = TermWeightSchedule("collision", start=1.0, end=3.0, fraction=0.5)
    # 10 updates: the weight moves over the first 5 rollouts, 0.4 per rollout, then stays
    got = [schedule.weight(i, 10) for i in range(10)]
    assert got == pytest.approx([1.0, 1.4, 1.8, 2.2, 2.6, 3.0, 3.0, 3.0, 3.0, 3.0])
    # a late ramp: held at 1 up to rollout 6 (begin * T), then 0.5 per rollout up to 3
    late = TermWeightSchedule("collision", start=1.0, end=3.0, fraction=0.4, begin=0.6)
    assert [late.weight(i, 10) for i in range(10)] == pytest.approx([1.0] * 7 + [1.5, 2.0, 2.5])
    assert late.weight(10, 10) == 3.0
    bads = ({"fraction": 0}, {"fraction": 1.5}, {"start": float("nan")}, {"end": "3"})
    bads += ({"begin": 1.0}, {"begin": -0.1}, {"begin": True})
    for bad in bads:
        with pytest.raises(ConfigError, match="TermWeightSchedule"):
            TermWeightSchedule(**{"term": "collision", "start": 1.0, "end": 3.0, **bad})


@pytest.mark.parametrize("overlap", [False, True])
def test_term_weight_schedule_sets_each_rollout_and_runs_repeat_exactly(overlap):
    runs = []
    for _ in range(2):
        spy, logger = WeightSpy(), ListLogger()
        schedule = TermWeightSchedule("collision", start=1.0, end=2.0)
        trainer = make_trainer([schedule, spy], overlap_collection=overlap)
        trainer.train(logger=logger)
        runs.append((spy.weights, [row["schedule/collision_weight"] for row in logger.rows], trainer))
    (weights, logged, a), (weights_b, logged_b, b) = runs
    per_rollout = [1.0, 1.2, 1.4, 1.6, 1.8]  # 5 updates, the weight moving over all of them
    assert logged == pytest.approx(per_rollout) and logged_b == logged
    # every step of rollout i ran at rollout i's weight (with overlap, one more rollout is in hand)
    assert weights[: 5 * T] == pytest.approx([w for w in per_rollout for _ in range(T)])
    assert weights_b == weights
    for name, p in a.model.state_dict().items():
        assert torch.equal(p, b.model.state_dict()[name]), name


class WeightLog:
    """Keeps a copy of the model's weights after every update (listed before the averaging)."""

    def __init__(self) -> None:
        self.states: list[dict[str, torch.Tensor]] = []

    def on_update(self, trainer, metrics) -> None:
        self.states.append({k: v.detach().clone() for k, v in trainer.model.state_dict().items()})


def test_weight_averaging_window_and_mean_by_hand():
    cb = WeightAveraging(fraction=0.2)
    assert [cb.first_update(n) for n in (10, 854, 3, 1)] == [9, 684, 3, 1]  # last 2, 171, 1, 1
    assert WeightAveraging(fraction=1.0).first_update(10) == 1

    class Model(torch.nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self.w = torch.nn.Parameter(torch.zeros(2))
            self.register_buffer("steps", torch.zeros((), dtype=torch.long))

    class Fake:  # the two attributes the callback reads
        total_updates, update_idx, model = 10, 0, Model()

    fake = Fake()
    for i in range(1, 11):  # update i leaves w = [i, -i] and the counter at i
        fake.update_idx = i
        with torch.no_grad():
            fake.model.w.copy_(torch.tensor([i, -i], dtype=torch.float32))
            fake.model.steps.fill_(i)
        logged = cb.on_update(fake, {})
    assert logged == {"averaging/updates": 2.0} and cb.count == 2
    cb.on_end(fake, {})
    assert fake.model.w.tolist() == [9.5, -9.5]  # mean of updates 9 and 10
    assert int(fake.model.steps) == 10  # an integer buffer keeps its last value
    for bad in (0, 1.5, -0.1, True, "0.2"):
        with pytest.raises(ConfigError, match=r"WeightAveraging fraction: expected a number in \(0, 1\]"):
            WeightAveraging(fraction=bad)


@pytest.mark.parametrize("overlap", [False, True])
def test_weight_averaging_ends_with_the_mean_and_survives_a_resume(tmp_path, overlap):
    torch.set_num_threads(1)  # as in test_overlap.py: the same bits in every run of the process
    steps = 5 * 3 * 4 * 12  # 5 updates of 3 worlds x 4 slots x 12 steps; averaged: the last 3
    log, avg = WeightLog(), WeightAveraging(fraction=0.6)
    a = resume_trainer(tmp_path / "a", 0, total_steps=steps, overlap_collection=overlap, callbacks=[log, avg])
    a.train(4)  # inside the window: updates 3 and 4 are in the sum
    a.save(tmp_path / "mid.pt")
    a.train()
    assert avg.count == 3
    moved = 0
    for name, value in a.model.state_dict().items():
        if value.is_floating_point():
            mean = sum(s[name].double() for s in log.states[2:]) / 3
            torch.testing.assert_close(value, mean.to(value.dtype), rtol=0, atol=1e-7, msg=name)
            moved += not torch.equal(value, log.states[-1][name])
    assert moved > 0  # the mean is not the last update's weights
    b_avg = WeightAveraging(fraction=0.6)
    b = resume_trainer(
        tmp_path / "b", 1, total_steps=steps, overlap_collection=overlap, callbacks=[WeightLog(), b_avg]
    )
    b.load(tmp_path / "mid.pt")
    b.train()
    assert b_avg.count == 3
    for name, value in a.model.state_dict().items():
        assert torch.equal(value, b.model.state_dict()[name]), name


def test_weight_averaging_from_the_trainer_config():
    target = "selfplaydrive.trainers.callbacks.WeightAveraging"
    cfg = compose("train", [f"trainer.callbacks=[{{_target_: {target}, fraction: 0.3}}]"])
    config = instantiate(cfg.trainer)
    assert isinstance(config.callbacks[0], WeightAveraging) and config.callbacks[0].fraction == 0.3
