"""`models.widen`: a narrow Deep Sets policy copied into wider sizes computes the same actions
and values, its copies can grow apart, and a checkpoint that cannot be widened is refused."""

from __future__ import annotations

import pytest

torch = pytest.importorskip("torch")

from selfplaydrive.errors import CheckpointError  # noqa: E402
from selfplaydrive.models import DeepSetsModel, TransformerModel  # noqa: E402
from selfplaydrive.models.widen import widen_deepsets_state  # noqa: E402
from selfplaydrive.obs.layout import ObsLayout  # noqa: E402

LAYOUT = ObsLayout(max_objects=5, max_road=7)
NARROW = {"input_size": 8, "hidden_size": 16, "lstm_size": 12}
WIDE = {"input_size": 16, "hidden_size": 48, "lstm_size": 24}  # factors 2, 3, 2


def _obs(gen: torch.Generator, batch: int) -> torch.Tensor:
    """Random observations whose valid flags are 0 or 1 (some slots padding)."""
    obs = torch.randn(batch, LAYOUT.obs_dim, generator=gen)
    s = LAYOUT.split(obs.numpy())  # views: writing them writes `obs`
    for block, kind in (("objects", "object"), ("road", "road")):
        col = LAYOUT.feature_index(kind, "valid")
        s[block][..., col] = (torch.rand(s[block].shape[:2], generator=gen) < 0.6).numpy()
    return obs


def _models(jitter: float = 0.5) -> tuple[DeepSetsModel, DeepSetsModel]:
    torch.manual_seed(0)
    narrow = DeepSetsModel(LAYOUT, (7, 13), **NARROW)
    with torch.no_grad():  # LayerNorm starts at 1 / 0: make its parameters matter
        for name, p in narrow.named_parameters():
            p.add_(0.3 * torch.randn_like(p)) if ".1." in name else None
    wide = DeepSetsModel(LAYOUT, (7, 13), **WIDE)
    gen = torch.Generator().manual_seed(1)
    wide.load_state_dict(widen_deepsets_state(narrow.state_dict(), wide, jitter=jitter, generator=gen))
    return narrow, wide


def test_the_widened_model_acts_and_values_as_the_narrow_one_over_a_rollout():
    narrow, wide = _models()
    gen = torch.Generator().manual_seed(2)
    batch = 6
    sn, sw = narrow.initial_state(batch), wide.initial_state(batch)
    with torch.no_grad():
        for t in range(5):
            obs = _obs(gen, batch)
            start = torch.tensor([t == 0] + [t == 3] * (batch - 1))
            ln, vn, sn = narrow(obs, sn, start)
            lw, vw, sw = wide(obs, sw, start)
            torch.testing.assert_close(lw, ln, atol=1e-5, rtol=1e-5)
            torch.testing.assert_close(vw, vn, atol=1e-5, rtol=1e-5)
        seq = torch.stack([_obs(gen, batch) for _ in range(4)])
        starts = torch.zeros(4, batch, dtype=torch.bool)
        starts[2, 1] = True
        ln, vn, _ = narrow.forward_sequence(seq, narrow.initial_state(batch), starts)
        lw, vw, _ = wide.forward_sequence(seq, wide.initial_state(batch), starts)
    torch.testing.assert_close(lw, ln, atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(vw, vn, atol=1e-5, rtol=1e-5)


def test_split_weights_share_the_old_weight_and_jitter_makes_copies_grow_apart():
    narrow, wide = _models()
    old, new = narrow.actor.weight, wide.actor.weight  # lstm 12 -> 24: two copies per unit
    torch.testing.assert_close(new[:, :12] + new[:, 12:], old)
    share = (new[:, :12] / old).detach()
    assert float(share.min()) > 0 and float(share.max()) < 1 and float(share.std()) > 0.05
    # the copies of a hidden unit get other gradients, so one step moves them apart
    obs = _obs(torch.Generator().manual_seed(3), 6)
    logits, value, _ = wide(obs, wide.initial_state(6), torch.ones(6, dtype=torch.bool))
    (logits.square().sum() + value.sum()).backward()
    g = wide.lstm.weight_ih_l0.grad.reshape(4, 2, 12, -1)
    assert not torch.allclose(g[:, 0], g[:, 1])


def test_equal_shares_keep_the_copies_identical():
    narrow, wide = _models(jitter=0.0)
    torch.testing.assert_close(wide.actor.weight[:, :12], narrow.actor.weight / 2)
    hh = wide.lstm.weight_hh_l0.reshape(4, 2, 12, 24)  # gate, copy, unit, input
    torch.testing.assert_close(hh[:, 0], hh[:, 1])


@pytest.mark.parametrize(
    ("wide", "expected"),
    [
        (lambda: DeepSetsModel(LAYOUT, (7, 13), **{**NARROW, "input_size": 12}), "input_size from 8 to 12"),
        (lambda: DeepSetsModel(LAYOUT, (7, 13), **{**NARROW, "hidden_size": 8}), "hidden_size from 16 to 8"),
        (
            lambda: DeepSetsModel(ObsLayout(max_objects=5, max_road=7, extra_dim=2), (7, 13), **WIDE),
            "ego_encoder.0.weight has shape (8, ",
        ),
        (lambda: DeepSetsModel(LAYOUT, (5, 13), **WIDE), "actor.weight"),
        (lambda: TransformerModel(LAYOUT, (7, 13)), "needs model=deepsets"),
    ],
)
def test_what_cannot_be_widened_is_refused_by_name(wide, expected):
    torch.manual_seed(0)
    narrow = DeepSetsModel(LAYOUT, (7, 13), **NARROW)
    with pytest.raises(CheckpointError, match=expected.replace("(", r"\(").replace(")", r"\)")):
        widen_deepsets_state(narrow.state_dict(), wide())
