"""The trainer's throughput paths (issue #16): acting evaluates only the slots that act,
minibatches hold only the slots that acted, models with `forward_sequence(..., active=...)`
skip the entries without loss, and spinning OpenMP threads are warned about."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from ppo_helpers import TinyPolicy, lane_env

from selfplaydrive.models import DeepSetsModel
from selfplaydrive.trainers import PPOConfig, PPOTrainer
from selfplaydrive.trainers.ppo import trainer as trainer_module

CFG = dict(
    total_steps=10_000,
    rollout_length=8,
    num_minibatches=2,
    num_epochs=2,
    device="cpu",
    progress_bar=False,
    checkpoint_interval=0,
    torch_threads=1,
)


def make_trainer(model_cls: type = TinyPolicy) -> PPOTrainer:
    torch.manual_seed(0)
    env = lane_env(num_worlds=4, episode_length=1.5)  # 2-4 agents in 4 slots per world
    if model_cls is TinyPolicy:
        model = TinyPolicy(env.layout.obs_dim)
    else:
        model = DeepSetsModel(env.layout, input_size=16, hidden_size=32, lstm_size=32)
    return PPOTrainer(env, model, PPOConfig(**CFG))


def test_act_evaluates_only_the_acting_slots():
    trainer = make_trainer()
    trainer.reset_env(seed=0)
    acting = torch.from_numpy(trainer.env.masks.copy())
    assert acting.any() and not acting.all()  # some slots are padding
    trainer.state = (torch.randn(trainer.num_slots, trainer.model.hidden),)
    before = trainer.state[0].clone()
    obs = torch.from_numpy(trainer.env.observations.copy())
    rows = torch.nonzero(acting).flatten()
    with torch.no_grad():
        _, expected_value, (expected_h,) = trainer.model(obs[rows], (before[rows],), trainer.next_start[rows])
    _, actions, logprobs, values, acted = trainer.act()
    assert torch.equal(acted, acting)
    idle = ~acting
    assert not actions[idle].any() and not logprobs[idle].any() and not values[idle].any()
    torch.testing.assert_close(values[rows], expected_value)
    assert (logprobs[rows] < 0).all()
    assert torch.equal(trainer.state[0][idle], before[idle])  # untouched: reset before reuse
    torch.testing.assert_close(trainer.state[0][rows], expected_h)


def test_minibatches_hold_only_slots_that_acted(monkeypatch):
    trainer = make_trainer()
    trainer.collect()
    trainer.compute_advantages()
    live = set(torch.nonzero(trainer.storage.active.any(dim=0)).flatten().tolist())
    assert 0 < len(live) < trainer.num_slots
    seen: list[list[int]] = []
    original = trainer.minibatch_loss

    def record(slots):
        seen.append(slots.tolist())
        return original(slots)

    monkeypatch.setattr(trainer, "minibatch_loss", record)
    trainer.update()
    cfg = trainer.config
    assert len(seen) == cfg.num_epochs * cfg.num_minibatches
    for epoch in range(cfg.num_epochs):
        batches = seen[epoch * cfg.num_minibatches : (epoch + 1) * cfg.num_minibatches]
        flat = [s for b in batches for s in b]
        assert sorted(flat) == sorted(live)  # every live slot once per epoch, nothing else


def test_models_with_an_active_argument_skip_entries_without_loss():
    assert make_trainer(DeepSetsModel).skip_inactive
    assert not make_trainer(TinyPolicy).skip_inactive  # its forward_sequence has no `active`


def test_deepsets_training_is_reproducible_with_the_fast_paths():
    def run() -> list[np.ndarray]:
        trainer = make_trainer(DeepSetsModel)
        trainer.train(num_updates=2)
        return [p.detach().numpy().copy() for p in trainer.model.parameters()]

    a, b = run(), run()
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))


@pytest.mark.parametrize(
    ("env", "threads", "warns"),
    [
        ({"GOMP_SPINCOUNT": "20000"}, 2, True),
        ({"GOMP_SPINCOUNT": "20000", "OMP_WAIT_POLICY": "passive"}, 2, False),
        ({"GOMP_SPINCOUNT": "20000"}, 1, False),
        ({}, 2, False),
    ],
)
def test_spinning_torch_threads_are_warned_about(monkeypatch, recwarn, env, threads, warns):
    monkeypatch.delenv("OMP_WAIT_POLICY", raising=False)
    monkeypatch.delenv("GOMP_SPINCOUNT", raising=False)
    for key, value in env.items():
        monkeypatch.setenv(key, value)
    monkeypatch.setattr(trainer_module.torch, "get_num_threads", lambda: threads)
    trainer_module.warn_spinning_threads(torch.device("cpu"))
    messages = [str(w.message) for w in recwarn if issubclass(w.category, RuntimeWarning)]
    assert bool(messages) == warns
    if warns:
        assert "OMP_WAIT_POLICY=passive" in messages[0]
