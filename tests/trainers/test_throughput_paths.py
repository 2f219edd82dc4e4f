"""The trainer's throughput paths (issue #16): acting evaluates only the slots that act,
minibatches hold only the slots that acted, models with `forward_sequence(..., active=...)`
skip the entries without loss, spinning OpenMP threads are warned about; the Deep Sets' fast
layers (fused LSTM cell for one step, the input layer's weight gradient, the pooling kernels)
give the plain computation's values, and `trainer.compile` swaps in the compiled pooling."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from ppo_helpers import TinyPolicy, lane_env

from selfplaydrive.errors import ConfigError
from selfplaydrive.models import DeepSetsModel
from selfplaydrive.models import pooling as model_pooling
from selfplaydrive.models.deepsets import _InputLinear
from selfplaydrive.models.pooling import EAGER_POOLING, PoolKernels, encode_max
from selfplaydrive.obs.layout import ObsLayout
from selfplaydrive.trainers import PPOConfig, PPOTrainer
from selfplaydrive.trainers.ppo.device import warn_spinning_threads

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


def make_trainer(model_cls: type = TinyPolicy, **config: object) -> PPOTrainer:
    torch.manual_seed(0)
    env = lane_env(num_worlds=4, episode_length=1.5)  # 2-4 agents in 4 slots per world
    if model_cls is TinyPolicy:
        model = TinyPolicy(env.layout.obs_dim)
    else:
        model = DeepSetsModel(env.layout, input_size=16, hidden_size=32, lstm_size=32)
    return PPOTrainer(env, model, PPOConfig(**{**CFG, **config}))


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
    monkeypatch.setattr(torch, "get_num_threads", lambda: threads)
    warn_spinning_threads(torch.device("cpu"))
    messages = [str(w.message) for w in recwarn if issubclass(w.category, RuntimeWarning)]
    assert bool(messages) == warns
    if warns:
        assert "OMP_WAIT_POLICY=passive" in messages[0]


def test_every_slot_is_kept_when_too_few_acted():
    trainer = make_trainer()
    trainer.collect()
    trainer.storage.active.zero_()
    trainer.storage.active[:, 5] = True  # one live slot, two minibatches
    assert trainer._live_slots().tolist() == list(range(trainer.num_slots))
    trainer.storage.active[:, 9] = True
    assert trainer._live_slots().tolist() == [5, 9]


def test_one_step_forward_equals_the_lstm_module():
    torch.manual_seed(3)
    model = DeepSetsModel(ObsLayout(max_objects=4, max_road=12), input_size=8, hidden_size=16, lstm_size=16)
    obs = torch.rand(5, model.splitter.layout.obs_dim)
    state = (torch.randn(5, 16), torch.randn(5, 16))
    start = torch.tensor([True, False, False, True, False])
    logits, value, (h, c) = model(obs, state, start)
    keep = (~start).float().unsqueeze(1)
    x = model.encode(obs).unsqueeze(0)
    out, (h_ref, c_ref) = model.lstm(x, ((state[0] * keep).unsqueeze(0), (state[1] * keep).unsqueeze(0)))
    torch.testing.assert_close(h, h_ref[0])
    torch.testing.assert_close(c, c_ref[0])
    torch.testing.assert_close(logits, model.actor(out[0]))
    torch.testing.assert_close(value, model.critic(out[0]).squeeze(-1))


def test_input_linear_has_the_values_gradients_and_keys_of_a_linear():
    torch.manual_seed(4)
    fast = _InputLinear(9, 6)
    plain = torch.nn.Linear(9, 6)
    plain.load_state_dict(fast.state_dict())
    assert fast.state_dict().keys() == plain.state_dict().keys()
    x = torch.randn(7, 5, 9)
    weight = torch.randn(7, 5, 6)
    for layer in (fast, plain):
        (layer(x) * weight).sum().backward()
    torch.testing.assert_close(fast(x), plain(x))
    torch.testing.assert_close(fast.weight.grad, plain.weight.grad)
    torch.testing.assert_close(fast.bias.grad, plain.bias.grad)
    assert fast.weight.grad.is_contiguous()


def counting_kernels(calls: list[str]) -> PoolKernels:
    """The eager kernels, recording which one ran."""

    def wrap(name: str):
        kernel = getattr(EAGER_POOLING, name)

        def run(*args):
            calls.append(name)
            return kernel(*args)

        return run

    return PoolKernels(winners=wrap("winners"), maximum=wrap("maximum"), full=wrap("full"))


@pytest.mark.parametrize(
    ("n", "grad", "expected"), [(40, True, "winners"), (40, False, "maximum"), (4, True, "full")]
)
def test_encode_max_runs_the_kernel_of_its_path(n, grad, expected):
    torch.manual_seed(5)
    enc = DeepSetsModel(ObsLayout(max_objects=2, max_road=2), input_size=8).road_encoder
    x = torch.rand(6, n, enc[0].in_features)
    valid = torch.rand(6, n) < 0.8
    calls: list[str] = []
    with torch.set_grad_enabled(grad):
        out = encode_max(enc, x, valid, 8, counting_kernels(calls))
        torch.testing.assert_close(out, encode_max(enc, x, valid, 8))
    assert calls and set(calls) == {expected}


def test_trainer_compile_option(monkeypatch, recwarn):
    with pytest.raises(ConfigError, match="compile"):
        PPOConfig(compile="yes")
    made: list[PoolKernels] = []

    def fake_compiled(cls):  # no real compiling in the default suite (tens of seconds)
        made.append(cls())
        return made[-1]

    monkeypatch.setattr(model_pooling.PoolKernels, "compiled", classmethod(fake_compiled))
    assert make_trainer(DeepSetsModel).model.pool_kernels is EAGER_POOLING  # off by default
    trainer = make_trainer(DeepSetsModel, compile=True)
    assert trainer.compiled and trainer.model.pool_kernels is made[0]
    assert not make_trainer(TinyPolicy, compile=True).compiled  # no compiled path: warned
    assert any("no compiled path" in str(w.message) for w in recwarn)


@pytest.mark.slow
@pytest.mark.parametrize("width", [8, 16, 32])  # torch's max below 16 dimensions; set_amax groups 16
def test_compiled_pooling_matches_eager_values_and_gradients(width: int):
    torch.manual_seed(6)
    enc = DeepSetsModel(ObsLayout(max_objects=2, max_road=2), input_size=width).road_encoder
    x = torch.rand(20, 80, enc[0].in_features)
    valid = torch.rand(20, 80) < 0.8
    weight = torch.randn(20, width)
    compiled = PoolKernels.compiled()
    grads = []
    for kernels in (EAGER_POOLING, compiled):
        enc.zero_grad()
        out = encode_max(enc, x, valid, width, kernels)
        (out * weight).sum().backward()
        grads.append((out.detach(), [p.grad.clone() for p in enc.parameters()]))
    torch.testing.assert_close(grads[0][0], grads[1][0])
    for a, b in zip(grads[0][1], grads[1][1], strict=True):
        torch.testing.assert_close(a, b, atol=1e-5, rtol=1e-5)
