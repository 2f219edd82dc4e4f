"""Grow a trained Deep Sets policy into a wider one that computes the same function.

A policy trained at the laptop's sizes (`model=deepsets_laptop`: 32-wide embeddings, an MLP and
LSTM of 128) can start a run of the paper's sizes (64 / 256 / 256, section 3) without losing what
it learnt: `selfplaydrive train model=deepsets init_from=<narrow .pt> init_widen=true`.

Every unit of a widened layer is copied `k` times (new unit j is old unit j mod n, `k` = new
width / old width, an integer per size). A layer that reads copied units splits each old input
weight among the copies with random shares that sum to 1, so its output is unchanged, while the
copies receive different gradients and can grow apart in training (Net2Net's wider-net
construction, Chen et al. 2016). LayerNorm keeps the function exactly: the mean and variance of
k copies of a vector are the vector's own. In the LSTM every gate block is widened alike, so each
copy of a hidden unit carries the same cell state as its original.
"""

from __future__ import annotations

from collections.abc import Mapping

from selfplaydrive._optional import requires_extra
from selfplaydrive.errors import CheckpointError

with requires_extra("torch"):
    import torch
    from torch import Tensor, nn

ENCODERS = ("ego_encoder", "object_encoder", "road_encoder")
GATES = 4  # the LSTM's input, forget, cell and output blocks, stacked in its weights' rows


def _factor(name: str, old: int, new: int) -> int:
    if new % old != 0 or new < old:
        raise CheckpointError(
            f"cannot widen {name} from {old} to {new}; expected the new size to be a whole multiple of the "
            "checkpoint's (e.g. the laptop's 32 / 128 / 128 into the paper's 64 / 256 / 256)"
        )
    return new // old


def _copy_rows(t: Tensor, k: int, blocks: int = 1) -> Tensor:
    """Dim 0 of `t` holds `blocks` blocks of units; each block is tiled k times."""
    b = t.reshape(blocks, 1, -1, *t.shape[1:])
    return b.expand(blocks, k, *b.shape[2:]).reshape(-1, *t.shape[1:])


def _split_cols(t: Tensor, k: int, jitter: float, gen: torch.Generator, blocks: int = 1) -> Tensor:
    """Dim 1 of `t` holds `blocks` blocks of input units, each now read from k copies: each weight
    is shared among its copies by random fractions (1 + jitter e) / k that sum to 1 per weight."""
    rows, cols = t.shape
    b = t.reshape(rows, blocks, 1, cols // blocks)
    u = torch.rand((rows, blocks, k, cols // blocks), generator=gen, dtype=t.dtype) * 2 - 1
    share = (1 + jitter * (u - u.mean(dim=2, keepdim=True))) / k
    return (b * share).reshape(rows, -1)


def widen_deepsets_state(
    state: Mapping[str, Tensor],
    model: nn.Module,
    jitter: float = 0.5,
    generator: torch.Generator | None = None,
) -> dict[str, Tensor]:
    """Weights for `model` (a `DeepSetsModel`) that compute what the narrower `state` computes.

    Args:
        state: A `DeepSetsModel`'s state dict (a checkpoint's "model"), of the same observation
            layout and actions as `model`, each size dividing `model`'s.
        model: The wider model; its sizes are read from its attributes.
        jitter: How unequal the shares of a split weight are (0: equal shares, the copies then
            stay identical in training; below 1 every share is positive).
        generator: Source of the shares (torch's global generator when None).

    Returns:
        A state dict for `model.load_state_dict`.

    Raises:
        CheckpointError: `model` is not a Deep Sets model, `state` is not one of the same
            layout, or a size does not divide the new one.
    """
    from selfplaydrive.models.deepsets import DeepSetsModel

    if not isinstance(model, DeepSetsModel):
        raise CheckpointError(f"init_widen needs model=deepsets*, got {type(model).__name__}")
    if not 0 <= jitter < 1:
        raise CheckpointError(f"widening jitter must be in [0, 1), got {jitter}")
    own = model.state_dict()
    missing = sorted(set(own) ^ set(state))
    if missing:
        raise CheckpointError(
            f"its weights are not a Deep Sets model's (keys {missing[:4]} differ); cannot widen"
        )
    gen = generator if generator is not None else torch.default_generator
    w0, h0 = state["ego_encoder.0.weight"].shape[0], state["shared.1.weight"].shape[0]
    l0 = state["lstm.weight_hh_l0"].shape[1]
    kw = _factor("input_size", w0, model.input_size)
    kh = _factor("hidden_size", h0, model.hidden_size)
    kl = _factor("lstm_size", l0, model.lstm_size)
    out: dict[str, Tensor] = {}
    for enc in ENCODERS:
        out[f"{enc}.0.weight"] = _copy_rows(state[f"{enc}.0.weight"], kw)
        for p in ("0.bias", "1.weight", "1.bias", "3.bias"):
            out[f"{enc}.{p}"] = _copy_rows(state[f"{enc}.{p}"], kw)
        out[f"{enc}.3.weight"] = _copy_rows(_split_cols(state[f"{enc}.3.weight"], kw, jitter, gen), kw)
    # the shared MLP reads [ego, objects, road], three blocks of embeddings
    out["shared.1.weight"] = _copy_rows(_split_cols(state["shared.1.weight"], kw, jitter, gen, blocks=3), kh)
    out["shared.1.bias"] = _copy_rows(state["shared.1.bias"], kh)
    out["lstm.weight_ih_l0"] = _copy_rows(_split_cols(state["lstm.weight_ih_l0"], kh, jitter, gen), kl, GATES)
    out["lstm.weight_hh_l0"] = _copy_rows(_split_cols(state["lstm.weight_hh_l0"], kl, jitter, gen), kl, GATES)
    for p in ("bias_ih_l0", "bias_hh_l0"):
        out[f"lstm.{p}"] = _copy_rows(state[f"lstm.{p}"], kl, GATES)
    for head in ("actor", "critic"):
        out[f"{head}.weight"] = _split_cols(state[f"{head}.weight"], kl, jitter, gen)
        out[f"{head}.bias"] = state[f"{head}.bias"].clone()
    for key, value in out.items():
        if value.shape != own[key].shape:
            raise CheckpointError(
                f"its {key} has shape {tuple(state[key].shape)}, which widens to {tuple(value.shape)}, "
                f"not this model's {tuple(own[key].shape)}; expected the same observation layout and actions"
            )
    return out
