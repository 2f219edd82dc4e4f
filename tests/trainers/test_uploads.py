"""Device uploads and mixed precision (issue #16 item 4). CUDA itself is not needed: the
page-locking path is checked with a stand-in for `torch.cuda.cudart()` (what the device
machine ran is in docs/benchmarks.md, "GPU"), and bf16 autocast with the CPU's autocast."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from ppo_helpers import lane_env

from selfplaydrive.errors import ConfigError
from selfplaydrive.models import DeepSetsModel, TransformerModel
from selfplaydrive.trainers import PPOConfig
from selfplaydrive.trainers.ppo import uploads
from selfplaydrive.trainers.ppo.uploads import Uploader


class FakeCudart:
    """Records cudaHostRegister / cudaHostUnregister calls; returns `code` from register."""

    def __init__(self, code: int = 0) -> None:
        self.code, self.registered, self.unregistered = code, [], []

    def cudaHostRegister(self, ptr: int, size: int, flags: int) -> int:  # noqa: N802 (CUDA's name)
        self.registered.append((ptr, size, flags))
        return self.code

    def cudaHostUnregister(self, ptr: int) -> int:  # noqa: N802
        self.unregistered.append(ptr)
        return 0


def test_cpu_uploads_are_private_copies():
    up = Uploader(torch.device("cpu"))
    a = np.arange(6, dtype=np.float32).reshape(2, 3)
    t = up(a, "obs")
    a[0, 0] = 99.0  # the env overwrites its buffers in the next step
    assert t[0, 0].item() == 0.0 and t.shape == (2, 3)


def test_registered_views_read_the_env_buffer_and_register_each_buffer_once(monkeypatch):
    fake = FakeCudart()
    monkeypatch.setattr(uploads.torch.cuda, "cudart", lambda: fake)
    up = Uploader(torch.device("cuda"))  # no CUDA call until an upload
    env = lane_env(num_worlds=2, episode_length=1.0)
    obs = up._registered_view(env.observations, "obs")
    acted = up._registered_view(env.masks, "acted")
    masks = up._registered_view(env.masks, "masks")  # the same buffer as "acted"
    assert np.shares_memory(obs.numpy(), env.observations) and obs.shape == env.observations.shape
    assert masks.dtype == torch.bool and np.shares_memory(masks.numpy(), acted.numpy())
    assert [r[:2] for r in fake.registered] == [
        (env.observations.ctypes.data, env.observations.nbytes),
        (env.masks.ctypes.data, env.masks.nbytes),
    ]
    assert up._registered_view(env.observations, "obs") is obs  # cached: no second register
    assert len(fake.registered) == 2
    env.step(np.zeros((env.num_agents, 2), dtype=np.int64))
    np.testing.assert_array_equal(obs.numpy(), env.observations)  # reads what the env wrote
    pointers = list(up._registered)
    del up  # the finalizer unregisters what was registered
    assert fake.unregistered == pointers


def test_a_failed_registration_warns_and_stages_that_buffer(monkeypatch):
    fake = FakeCudart(code=712)  # cudaErrorHostMemoryAlreadyRegistered
    monkeypatch.setattr(uploads.torch.cuda, "cudart", lambda: fake)
    up = Uploader(torch.device("cuda"))
    with pytest.warns(RuntimeWarning, match="'obs' .* could not be page-locked .* 712"):
        assert up._registered_view(np.zeros((4, 3), dtype=np.float32), "obs") is None
    assert "obs" in up.failed and up._registered == []


def test_host_register_is_checked():
    with pytest.raises(ConfigError, match="host_register = 'yes': expected true or false"):
        PPOConfig(host_register="yes")


@pytest.mark.parametrize("model_cls", [DeepSetsModel, TransformerModel])
def test_bf16_autocast_keeps_float32_outputs_and_recurrent_state(model_cls):
    """Under autocast the skipped entries are filled in the computed part's dtype (CUDA's
    index_copy does not convert, and failed there), the LSTM runs and keeps its state in
    float32, and the values stay within bf16 rounding of float32."""
    torch.manual_seed(0)
    env = lane_env(num_worlds=2, episode_length=1.0)
    kw = (
        dict(input_size=16, hidden_size=32, lstm_size=32)
        if model_cls is DeepSetsModel
        else dict(embed_size=32, ffn_size=64, film_hidden=32)
    )
    model = model_cls(env.layout, **kw)
    t_len, b = 5, env.num_agents
    obs = torch.from_numpy(
        np.random.default_rng(0).normal(size=(t_len, b, env.layout.obs_dim)).astype(np.float32)
    )
    starts = torch.zeros(t_len, b, dtype=torch.bool)
    starts[2, 0] = True
    active = torch.ones(t_len, b, dtype=torch.bool)
    active[:, 1] = False
    state = model.initial_state(b)
    ref_logits, ref_values, _ = model.forward_sequence(obs, state, starts, active=active)
    with torch.autocast("cpu", dtype=torch.bfloat16):
        logits, values, new_state = model.forward_sequence(obs, state, starts, active=active)
    assert all(s.dtype == torch.float32 for s in new_state)
    assert torch.isfinite(logits).all() and torch.isfinite(values).all()
    assert (logits[:, 1] == 0).all() and (values[:, 1] == 0).all()  # skipped entries stay zero
    scale = ref_logits.abs().max().item() + 1e-6
    assert (logits.float() - ref_logits).abs().max().item() < 0.05 * scale + 0.05
    scale = ref_values.abs().max().item() + 1e-6
    assert (values.float() - ref_values).abs().max().item() < 0.05 * scale + 0.05
