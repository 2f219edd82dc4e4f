"""The throughput paths of the models (issue #16): `encode_max` (max found without autograd,
winners re-encoded) and `forward_sequence(..., active=...)` give the values and gradients of
the plain computation."""

from __future__ import annotations

import pytest
import torch
from torch import nn

from selfplaydrive.models import DeepSetsModel, TransformerModel
from selfplaydrive.models.pooling import (
    encode_max,
    few_winners,
    first_max_index,
    masked_max,
    padding_bias,
    set_amax,
)
from selfplaydrive.obs.layout import ObsLayout

LAYOUT = ObsLayout(max_objects=6, max_road=40)


@pytest.fixture(autouse=True, scope="module")
def _one_thread():
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


def encoder(in_dim: int, width: int, seed: int) -> nn.Sequential:
    torch.manual_seed(seed)
    return nn.Sequential(nn.Linear(in_dim, width), nn.LayerNorm(width), nn.GELU(), nn.Linear(width, width))


def sets(
    batch: int, n: int, features: int, seed: int, fill: float = 0.7
) -> tuple[torch.Tensor, torch.Tensor]:
    gen = torch.Generator().manual_seed(seed)
    x = torch.rand(batch, n, features, generator=gen) * 2 - 1
    valid = torch.rand(batch, n, generator=gen) < fill
    valid[0] = False  # a row without any element
    valid[1] = True  # a full row
    return x, valid


def grads(module: nn.Module, out: torch.Tensor, weight: torch.Tensor) -> list[torch.Tensor]:
    module.zero_grad()
    (out * weight).sum().backward()
    return [p.grad.clone() for p in module.parameters()]


@pytest.mark.parametrize(("n", "width"), [(40, 8), (5, 16)])
def test_encode_max_matches_masked_max_values_and_gradients(n: int, width: int) -> None:
    enc = encoder(3, width, seed=0)
    x, valid = sets(12, n, 3, seed=1)
    weight = torch.randn(12, width, generator=torch.Generator().manual_seed(2))
    plain = masked_max(enc(x), valid)
    fast = encode_max(enc, x, valid, width)
    torch.testing.assert_close(fast, plain, atol=1e-6, rtol=1e-6)
    assert torch.equal(fast[0], torch.zeros(width))  # the empty row
    for a, b in zip(grads(enc, fast, weight), grads(enc, plain, weight), strict=True):
        torch.testing.assert_close(a, b, atol=1e-5, rtol=1e-5)


def test_encode_max_without_autograd_matches_and_keeps_no_graph() -> None:
    enc = encoder(3, 8, seed=3)
    x, valid = sets(600, 40, 3, seed=4)  # several chunks of the gradient-free pass
    with torch.no_grad():
        plain = masked_max(enc(x), valid)
    with torch.inference_mode():
        fast = encode_max(enc, x, valid, 8)
    assert not fast.requires_grad
    torch.testing.assert_close(fast, plain, atol=1e-6, rtol=1e-6)


def test_encode_max_ignores_padding_values() -> None:
    enc = encoder(3, 8, seed=5)
    x, valid = sets(10, 40, 3, seed=6, fill=0.3)
    noisy = torch.where(valid.unsqueeze(-1), x, torch.full_like(x, 50.0))  # huge padding
    torch.testing.assert_close(encode_max(enc, noisy, valid, 8), encode_max(enc, x, valid, 8))


def test_masked_max_gradient_goes_to_the_winner_only() -> None:
    x = torch.tensor([[[1.0, 4.0], [3.0, 2.0], [9.0, 9.0]]], requires_grad=True)
    valid = torch.tensor([[True, True, False]])  # the 9s are padding
    out = masked_max(x, valid)
    assert out.tolist() == [[3.0, 4.0]]
    out.sum().backward()
    assert x.grad.tolist() == [[[0.0, 1.0], [1.0, 0.0], [0.0, 0.0]]]


@pytest.mark.parametrize(
    ("rows", "n", "width"), [(64, 1, 4), (300, 20, 32), (40, 64, 48), (9, 300, 33), (50, 7, 16), (30, 33, 16)]
)
def test_first_max_index_is_torch_max_indices_on_random_sets(rows: int, n: int, width: int) -> None:
    """The NumPy-free reference is torch's own `max(dim=1).indices` (the first maximum on the
    CPU): equal on random sets with exact ties, padding (-inf) and all-padding rows."""
    gen = torch.Generator().manual_seed(rows + n)
    x = torch.randn(rows, n, width, generator=gen)
    if n > 3:
        x[:, 3] = x[:, 1]  # exact ties: the first of them wins
        x[::3, 2] = x[::3, 1]
    valid = torch.rand(rows, n, generator=gen) < 0.6
    valid[0] = False  # every element padding
    x = x + padding_bias(valid)
    got = first_max_index(x)
    assert got.dtype == torch.int64 and got.shape == (rows, width)
    assert torch.equal(got, x.max(dim=1).indices)
    assert torch.equal(got[0], torch.zeros(width, dtype=torch.int64))


def test_first_max_index_by_hand() -> None:
    x = torch.tensor([[[1.0, 5.0], [3.0, 5.0], [3.0, -1.0]]])  # (1, 3, 2)
    assert first_max_index(x).tolist() == [[1, 0]]  # 3 first at element 1; 5 first at element 0
    wide = x.repeat(1, 1, 16)  # 32 dimensions: the vectorised path, not torch's max (below 16)
    assert first_max_index(wide).tolist() == [[1, 0] * 16]
    assert first_max_index(wide.to(torch.bfloat16)).tolist() == [[1, 0] * 16]


@pytest.mark.parametrize(("n", "width"), [(1, 16), (3, 16), (7, 16), (64, 16), (9, 8), (20, 32), (5, 24)])
def test_set_amax_is_amax_over_the_set(n: int, width: int) -> None:
    """Narrow embeddings are reduced 32 wide (g elements side by side, the rest on their own):
    the values must be torch's `amax` exactly, with padding and all-padding rows."""
    gen = torch.Generator().manual_seed(n * width)
    x = torch.randn(41, n, width, generator=gen)
    valid = torch.rand(41, n, generator=gen) < 0.6
    valid[0] = False
    x = x + padding_bias(valid)
    assert torch.equal(set_amax(x), x.amax(dim=1))


def test_padding_bias_is_masked_fill_with_minus_inf() -> None:
    gen = torch.Generator().manual_seed(7)
    x = torch.randn(30, 12, 6, generator=gen)
    valid = torch.rand(30, 12, generator=gen) < 0.5
    expected = x.masked_fill(~valid.unsqueeze(-1), float("-inf"))
    assert torch.equal(x + padding_bias(valid), expected)
    assert padding_bias(valid).shape == (30, 12, 1)


def test_few_winners_decides_by_the_expected_winner_count() -> None:
    assert few_winners(64, 32) and few_winners(200, 64)  # road sets of the laptop and paper models
    assert not few_winners(16, 32)  # laptop objects: nearly every element wins some dimension
    assert not few_winners(1, 64)


def make_obs(batch: int, seed: int) -> torch.Tensor:
    gen = torch.Generator().manual_seed(seed)
    obs = torch.rand(batch, LAYOUT.obs_dim, generator=gen) * 2 - 1
    for lo, hi, width, col in (
        (
            LAYOUT.objects_offset,
            LAYOUT.road_offset,
            LAYOUT.object_dim,
            LAYOUT.feature_index("object", "valid"),
        ),
        (LAYOUT.road_offset, LAYOUT.extra_offset, LAYOUT.road_dim, LAYOUT.feature_index("road", "valid")),
    ):
        block = obs[:, lo:hi].view(batch, -1, width)
        valid = torch.rand(block.shape[:2], generator=gen) < 0.8
        block[..., col] = valid.float()
        block[~valid] = 0.0
    return obs


@pytest.mark.parametrize("cls", [DeepSetsModel, TransformerModel])
def test_active_entries_match_the_full_evaluation(cls: type) -> None:
    """PPO's case: entries that do not act carry no loss, and an agent's next acting entry
    starts its episode, so skipping them changes neither outputs nor gradients."""
    torch.manual_seed(0)
    model = cls(LAYOUT)
    t_len, batch = 6, 5
    obs = make_obs(t_len * batch, seed=1).view(t_len, batch, -1)
    active = torch.ones(t_len, batch, dtype=torch.bool)
    active[2:, 0] = False  # slot 0 ends after step 1
    active[:3, 3] = False  # slot 3 is empty until its agent starts at step 3
    active[:, 4] = False  # slot 4 never acts
    starts = torch.zeros(t_len, batch, dtype=torch.bool)
    starts[3, 3] = True
    state = tuple(torch.randn_like(s) for s in model.initial_state(batch))
    weight = torch.randn(t_len, batch)

    def run(**kwargs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, list[torch.Tensor]]:
        model.zero_grad()
        logits, values, _ = model.forward_sequence(obs, state, starts, **kwargs)
        loss = ((logits.sum(-1) + values) * weight * active).sum()
        loss.backward()
        return logits, values, [p.grad.clone() for p in model.parameters() if p.grad is not None]

    full_logits, full_values, full_grads = run()
    logits, values, part_grads = run(active=active)
    torch.testing.assert_close(logits[active], full_logits[active], atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(values[active], full_values[active], atol=1e-5, rtol=1e-5)
    assert len(part_grads) == len(full_grads)
    for a, b in zip(part_grads, full_grads, strict=True):
        torch.testing.assert_close(a, b, atol=1e-4, rtol=1e-4)


def test_active_mask_of_the_wrong_shape_is_refused() -> None:
    model = DeepSetsModel(LAYOUT)
    obs = make_obs(6, seed=2).view(3, 2, -1)
    starts = torch.zeros(3, 2, dtype=torch.bool)
    with pytest.raises(ValueError, match="active"):
        model.forward_sequence(obs, model.initial_state(2), starts, active=torch.ones(4, dtype=torch.bool))
