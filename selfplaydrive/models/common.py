"""Pieces shared by the policy models (paper section 3).

- `ObsSplitter`: cuts a flat (B, obs_dim) observation into per-modality tensors using the
  env's `ObsLayout`, so no model hard-codes column offsets.
- `masked_max`: the Deep Sets pooling with padded elements excluded.
- `compact_sets`: drops slots that are padding in every row of a batch (exact, a speed-up).
- MultiDiscrete helpers: split logits, sample, log-probability and entropy summed over the
  action dimensions (acceleration x steering by default, section 2.4).
- `check_nvec`, `mlp`: argument checking and small builders.

Every model returns, for a batch of B observations, concatenated logits (B, sum(nvec)), a
value (B,) and a recurrent state: a tuple of tensors (empty for feed-forward models).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, fields
from itertools import pairwise
from typing import Protocol, runtime_checkable

from selfplaydrive._optional import requires_extra
from selfplaydrive.maps.roadmap import SegmentType
from selfplaydrive.obs.layout import EGO_FEATURES, ObsLayout

with requires_extra("torch"):
    import torch
    from torch import Tensor, nn

State = tuple[Tensor, ...]

COEF_PREFIX = "coef_"
NUM_ROAD_TYPES = len(SegmentType)


@runtime_checkable
class PolicyModel(Protocol):
    """What a trainer needs from a policy (both `DeepSetsModel` and `TransformerModel`)."""

    nvec: tuple[int, ...]
    is_recurrent: bool

    def initial_state(self, batch_size: int, device: torch.device | str | None = None) -> State:
        """State for a fresh batch of agents (an empty tuple for feed-forward models)."""
        ...

    def forward(self, obs: Tensor, state: State, episode_start: Tensor) -> tuple[Tensor, Tensor, State]:
        """(B, obs_dim), state, (B,) bool -> logits (B, sum(nvec)), value (B,), new state."""
        ...

    def forward_sequence(
        self, obs: Tensor, state: State, episode_start: Tensor, active: Tensor | None = None
    ) -> tuple[Tensor, Tensor, State]:
        """(T, B, obs_dim), state, (T, B) bool -> logits (T, B, sum(nvec)), values (T, B), state.

        `active` (optional, (T, B) bool): only those entries' outputs are used (the others may
        be skipped); a trainer passes it only to models whose signature has it."""
        ...


def check_nvec(action_nvec: Sequence[int]) -> tuple[int, ...]:
    """Validate MultiDiscrete sizes.

    Args:
        action_nvec: Number of choices per action dimension, e.g. (7, 13).

    Returns:
        The sizes as a tuple of ints.

    Raises:
        ValueError: When empty or a size is below 1.
    """
    nvec = tuple(int(n) for n in action_nvec)
    if not nvec or any(n < 1 for n in nvec):
        raise ValueError(
            f"action_nvec: expected a non-empty sequence of ints >= 1, got {list(action_nvec)!r}"
        )
    return nvec


def check_positive(name: str, value: int) -> int:
    """Raise a ValueError naming `name` unless `value` is an int >= 1."""
    if int(value) != value or value < 1:
        raise ValueError(f"{name}: expected an int >= 1, got {value!r}")
    return int(value)


def orthogonal_(weight: Tensor, gain: float) -> Tensor:
    """`nn.init.orthogonal_` on one intra-op thread, restoring the caller's thread count.

    The QR decomposition behind it rounds differently with the number of threads (up to 2e-7
    here), and PPO amplifies that: the same seed gave a different model, and a different
    learning curve, depending on whether the process had called `torch.set_num_threads(1)`
    before building it. One thread makes the initial weights a function of the seed alone."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        return nn.init.orthogonal_(weight, gain)
    finally:
        torch.set_num_threads(threads)


def mlp(
    sizes: Sequence[int], activation: type[nn.Module] = nn.ReLU, final_act: bool = False
) -> nn.Sequential:
    """Linear layers of the given widths with `activation` between them.

    Args:
        sizes: [in, hidden..., out] widths.
        activation: Module class inserted after every layer but the last.
        final_act: Also apply the activation after the last layer.
    """
    layers: list[nn.Module] = []
    for i, (a, b) in enumerate(pairwise(sizes)):
        layers.append(nn.Linear(a, b))
        if i < len(sizes) - 2 or final_act:
            layers.append(activation())
    return nn.Sequential(*layers)


def as_layout(layout: ObsLayout | Mapping[str, int]) -> ObsLayout:
    """Accept an `ObsLayout` or its fields as a mapping (Hydra's `_convert_="all"` turns the
    dataclass into a dict on its way to the constructor)."""
    if isinstance(layout, ObsLayout):
        return layout
    if isinstance(layout, Mapping):
        names = [f.name for f in fields(ObsLayout)]
        unknown = sorted(set(layout) - set(names))
        if unknown:
            raise ValueError(f"layout: unknown keys {unknown}, expected a subset of {names}")
        return ObsLayout(**layout)
    raise TypeError(f"layout: expected an ObsLayout or a mapping of its fields, got {type(layout).__name__}")


class ObsSplitter(nn.Module):
    """Layout-driven split of flat observations into model inputs (paper section 2.5).

    Outputs of `forward(obs)`:
        ego: (B, ego_dim + extra_dim) ego features followed by the hook columns.
        coef: (B, C) the reward coefficients (ego features named `coef_*`, section 2.3).
        objects: (B, O, F_obj) object features; road: (B, R, F_road') road features with the
            segment `type` column replaced by a one-hot over `SegmentType` (as PufferDrive does).
        object_valid: (B, O) bool; road_valid: (B, R) bool.

    Args:
        layout: The env's observation layout.
        one_hot_road_type: Replace the scalar road `type` by a one-hot of `NUM_ROAD_TYPES`.
    """

    def __init__(self, layout: ObsLayout | Mapping[str, int], one_hot_road_type: bool = True) -> None:
        super().__init__()
        self.layout = layout = as_layout(layout)
        self.one_hot_road_type = one_hot_road_type
        coef = [i for i, name in enumerate(EGO_FEATURES) if name.startswith(COEF_PREFIX)]
        self.register_buffer("coef_index", torch.tensor(coef, dtype=torch.long), persistent=False)
        self.obj_valid_col = layout.feature_index("object", "valid")
        self.road_valid_col = layout.feature_index("road", "valid")
        self.road_type_col = layout.feature_index("road", "type")
        self.register_buffer("type_codes", torch.arange(NUM_ROAD_TYPES), persistent=False)

    @property
    def ego_in(self) -> int:
        """Width of the `ego` output: ego features plus hook columns."""
        return self.layout.ego_dim + self.layout.extra_dim

    @property
    def coef_in(self) -> int:
        """Number of reward-coefficient columns."""
        return int(self.coef_index.numel())

    @property
    def object_in(self) -> int:
        return self.layout.object_dim

    @property
    def road_in(self) -> int:
        return self.layout.road_dim - 1 + NUM_ROAD_TYPES if self.one_hot_road_type else self.layout.road_dim

    def forward(self, obs: Tensor) -> dict[str, Tensor]:
        lay = self.layout
        if obs.dim() != 2 or obs.shape[1] != lay.obs_dim:
            raise ValueError(f"obs: expected shape (B, {lay.obs_dim}) for {lay}, got {tuple(obs.shape)}")
        if not obs.is_floating_point():
            raise ValueError(f"obs: expected a floating-point tensor (float32), got {obs.dtype}")
        b = obs.shape[0]
        ego = obs[:, : lay.ego_dim]
        objects = obs[:, lay.objects_offset : lay.road_offset].reshape(b, lay.max_objects, lay.object_dim)
        road = obs[:, lay.road_offset : lay.extra_offset].reshape(b, lay.max_road, lay.road_dim)
        extra = obs[:, lay.extra_offset :]
        out = {
            "ego": torch.cat([ego, extra], dim=1) if lay.extra_dim else ego,
            "coef": ego.index_select(1, self.coef_index),
            "objects": objects,
            "object_valid": objects[..., self.obj_valid_col] > 0.5,
            "road": self._road_features(road),
            "road_valid": road[..., self.road_valid_col] > 0.5,
        }
        return out

    def _road_features(self, road: Tensor) -> Tensor:
        if not self.one_hot_road_type:
            return road
        col = self.road_type_col
        # The kernel writes type / (NUM_ROAD_TYPES - 1); round back to the class index.
        idx = torch.round(road[..., col] * (NUM_ROAD_TYPES - 1)).long().clamp(0, NUM_ROAD_TYPES - 1)
        one_hot = (idx.unsqueeze(-1) == self.type_codes).to(road.dtype)
        return torch.cat([road[..., :col], road[..., col + 1 :], one_hot], dim=-1)


def compact_sets(x: Tensor, valid: Tensor) -> tuple[Tensor, Tensor]:
    """Keep only as many slots as the fullest row has valid elements.

    Valid elements are moved to the front (stable order) and trailing all-padding slots are
    dropped. Both models are invariant to element order and ignore padding, so their outputs
    are unchanged; the cost of the set encoders and of attention drops with the slot count.

    Args:
        x: (B, N, F) element features.
        valid: (B, N) bool.

    Returns:
        (B, K, F) features and (B, K) validity, K = max valid count (at least 1).
    """
    k = max(int(valid.sum(dim=1).max().item()) if valid.numel() else 0, 1)
    if k >= valid.shape[1]:
        return x, valid
    order = torch.argsort(valid.to(torch.int8), dim=1, descending=True, stable=True)[:, :k]
    x = torch.gather(x, 1, order.unsqueeze(-1).expand(-1, -1, x.shape[-1]))
    return x, torch.gather(valid, 1, order)


def masked_max(x: Tensor, valid: Tensor) -> Tensor:
    """Element-wise maximum over a set, ignoring padded elements (Deep Sets, section 3).

    The maximum is found without autograd (argmax over the set) and then gathered, so the
    backward pass scatters each output gradient to the one element that won, instead of
    torch's amax backward, which compares every element with the maximum and divides by the
    tie count (about a fifth of a Deep Sets update on the CPU). Values are the same; only at
    exact ties does the gradient go to the first maximal element instead of being shared.

    Args:
        x: (B, N, D) per-element embeddings.
        valid: (B, N) bool, False for padding.

    Returns:
        (B, D) maximum over valid elements; zeros for a row without any valid element.
    """
    with torch.no_grad():
        winner = first_max_index(x + padding_bias(valid)).unsqueeze(1)
    pooled = x.gather(1, winner).squeeze(1)
    # a row without valid elements picked a padding element: zero it (the contract above)
    return torch.where(valid.any(dim=1, keepdim=True), pooled, 0.0)


def padding_bias(valid: Tensor) -> Tensor:
    """(R, N, 1) float32: 0 for the valid elements of (R, N) `valid`, -inf for padding. Added
    to (R, N, D) finite embeddings it gives `masked_fill(~valid, -inf)`, the same values, about
    6x faster on the CPU (a masked_fill with a broadcast bool mask takes its slow path)."""
    return torch.where(valid, 0.0, float("-inf")).unsqueeze(-1)


def set_amax(x: Tensor) -> Tensor:
    """(R, N, D) -> (R, D): `x.amax(dim=1)`, the same values, fast for narrow embeddings.

    torch's CPU `amax` over the set axis takes a slow path when a row has fewer than 32
    dimensions (16: 0.21-0.49 ms for a chunk of 16,384 elements, against 0.03-0.05 ms at 32;
    docs/benchmarks.md, "Trainer", session 37). A maximum does not depend on the order it is
    taken in, so for D dividing 32 the set is read as (R, N / g, g D) with g = 32 / D
    consecutive elements side by side, reduced at 32 wide, and the g partial maxima reduced
    last; elements left over when g does not divide N are reduced on their own. On other
    devices `amax` as it is (one kernel; more launches would cost there, unmeasured)."""
    r, n, d = x.shape
    g = 32 // d if d < 32 and 32 % d == 0 and x.device.type == "cpu" else 1
    if g == 1 or n < 2 * g:
        return x.amax(dim=1)
    m = n - n % g
    top = x[:, :m].reshape(r, m // g, g * d).amax(dim=1).view(r, g, d).amax(dim=1)
    if m < n:
        top = torch.maximum(top, x[:, m:].amax(dim=1))
    return top


def first_max_index(x: Tensor) -> Tensor:
    """(R, N, D) -> (R, D) int64: the index of the first maximum over the set axis, the same as
    `x.max(dim=1).indices` (which picks the first maximal element on the CPU).

    Made of vectorised whole-tensor ops: torch's CPU `max` with indices reduces the middle axis
    element by element, 3-5x slower (a chunk of 16,384 elements x 32 dimensions: 0.55-1.17 ms,
    against 0.20-0.32 ms here), and was the largest single op of a Deep Sets update with 32
    objects (docs/benchmarks.md, "Trainer", session 37). Each element scores its rank from the
    end of the set (N for the first, 1 for the last) where it equals the maximum and 0
    elsewhere; the largest score is the first maximum. `sign` (not a comparison) marks the
    maximum: torch's CPU comparisons, which write bools, are about 6x slower than float
    arithmetic here; and the steps work in place on one buffer, since every fresh buffer of a
    chunk's size costs more in page faults than the arithmetic does. Both maxima are taken by
    `set_amax`. A row whose elements are all -inf (padding) gives index 0, as `max` does.
    Below 16 dimensions torch's `max` is the faster (8: 0.11-0.26 ms against 0.16-0.40 ms)
    and is used; both give the same indices. So is it on other devices than the CPU, where it
    is one kernel against about ten (the GPU runs were measured with it; which of tied maxima
    it returns there is not documented)."""
    n, width = x.shape[1], x.shape[2]
    if width < 16 or x.device.type != "cpu":
        return x.max(dim=1).indices
    # float32 ranks whatever x's dtype: integers up to 2**24 exactly (bf16 only up to 256)
    rank = torch.arange(n, 0, -1, dtype=torch.float32, device=x.device).view(1, n, 1)
    score = (x - set_amax(x).unsqueeze(1)).float()  # 0 at the maximum, < 0 below it
    score.sign_().add_(1.0).mul_(rank)  # rank at the maximum, 0 below it
    first = set_amax(score)
    # -inf - -inf is nan in a row of padding; whether sign(nan) is 0 or nan, the index is 0
    return (n - first.nan_to_num_(nan=float(n))).long()


# Elements per chunk of the gradient-free pass of `encode_max`: with an embedding of 32-64
# floats, 2**14 elements are 2-4 MiB per intermediate, so a chunk's
# Linear -> LayerNorm -> GELU -> Linear -> max stays in the cache, and every intermediate stays
# below glibc's mmap threshold (32 MiB), which would otherwise map and page-fault fresh memory
# for every op (a third of an op's time at paper sizes).
POOL_CHUNK_ELEMENTS = 1 << 14


def _chunk_winners(encoder: nn.Module, x: Tensor, valid: Tensor | None) -> Tensor:
    """(R, D) index of the first maximal element of `encoder(x)` per row and dimension,
    padding (`valid` False; None: all valid) excluded. `x`: (R, N, F)."""
    emb = encoder(x)
    if valid is not None:
        emb.add_(padding_bias(valid))  # a temporary of this pass: in place
    return first_max_index(emb)


def _chunk_max(encoder: nn.Module, x: Tensor, valid: Tensor | None) -> Tensor:
    """(R, D) maximum of `encoder(x)` over the valid elements (-inf for a row without any)."""
    emb = encoder(x)
    if valid is not None:
        emb.add_(padding_bias(valid))
    return set_amax(emb)


def _encoded_max(encoder: nn.Module, x: Tensor, valid: Tensor) -> Tensor:
    """`masked_max(encoder(x), valid)`: every element encoded with autograd."""
    return masked_max(encoder(x), valid)


@dataclass(frozen=True)
class PoolKernels:
    """The computations `encode_max` is made of, eager or compiled (`compiled`).

    Attributes:
        winners: (encoder, x, valid | None) -> (R, D) first indices of the maximum.
        maximum: (encoder, x, valid | None) -> (R, D) maximum values.
        full: (encoder, x, valid) -> (R, D) `masked_max(encoder(x), valid)` with autograd.
    """

    winners: Callable[[nn.Module, Tensor, Tensor | None], Tensor] = _chunk_winners
    maximum: Callable[[nn.Module, Tensor, Tensor | None], Tensor] = _chunk_max
    full: Callable[[nn.Module, Tensor, Tensor], Tensor] = _encoded_max

    @classmethod
    def compiled(cls) -> PoolKernels:
        """The kernels under `torch.compile`: Linear -> LayerNorm -> GELU -> Linear -> max of a
        chunk becomes two matrix products and one fused loop, with a vectorised max over the
        set (docs/benchmarks.md, "Trainer": a laptop road chunk 1.35-2.5x faster, whole updates
        1.02x). Each function compiles on its first call per encoder (seconds; automatic
        dynamic shapes after the first change of a size), and the values equal the eager ones
        up to float rounding."""
        return cls(
            winners=torch.compile(_chunk_winners),
            maximum=torch.compile(_chunk_max),
            full=torch.compile(_encoded_max),
        )


EAGER_POOLING = PoolKernels()


def encode_max(
    encoder: nn.Module, x: Tensor, valid: Tensor, width: int, kernels: PoolKernels = EAGER_POOLING
) -> Tensor:
    """`masked_max(encoder(x), valid)`, computed without encoding every element with autograd.

    Only the elements that win the maximum in some embedding dimension receive gradient, so
    for sets much larger than the number of winners (`few_winners`) the maximum is found
    first without autograd (in cache-sized chunks of rows), and only the winners (at most one
    per dimension and row, fewer where one element wins several) are encoded again with
    autograd. The values equal `masked_max(encoder(x), valid)` up to float rounding; at exact
    ties the gradient goes to the first maximal element. `encoder` must act on each element
    independently (an MLP), as the Deep Sets encoders do.

    Args:
        encoder: Module mapping (..., F) to (..., width) element-wise.
        x: (B, N, F) element features.
        valid: (B, N) bool, False for padding.
        width: The encoder's output width D.
        kernels: The pooling computations (`PoolKernels`; `PoolKernels.compiled()` for the
            torch.compiled ones).

    Returns:
        (B, D) maximum over valid elements; zeros for a row without any valid element.
    """
    b, n = x.shape[:2]
    need_grad = torch.is_grad_enabled() and (
        x.requires_grad or any(p.requires_grad for p in encoder.parameters())
    )
    if b == 0 or n == 0 or (need_grad and not few_winners(n, width)):
        return kernels.full(encoder, x, valid)
    mask = None if bool(valid.all()) else valid  # all valid: the usual case for road segments
    rows = max(1, POOL_CHUNK_ELEMENTS // n)
    chunk = kernels.winners if need_grad else kernels.maximum
    with torch.no_grad():
        parts = [
            chunk(encoder, x[lo : lo + rows], None if mask is None else mask[lo : lo + rows])
            for lo in range(0, b, rows)
        ]
    pooled = _encode_winners(encoder, x, torch.cat(parts)) if need_grad else torch.cat(parts)
    return torch.where(valid.any(dim=1, keepdim=True), pooled, 0.0)


def few_winners(n: int, width: int) -> bool:
    """Whether re-encoding only the winners of a max over `n` elements and `width` dimensions
    beats one pass with autograd (about 3 forward passes, forward plus backward) over all.

    With independent maxima, `u = n (1 - (1 - 1/n) ** width)` elements win some dimension;
    the two-pass scheme costs about n + 3u forward passes, so it pays when u < 2n / 3 (road
    sets of 64 at width 32: u = 25; 200 at 64: u = 55; objects of 16 at 32: u = 14, it does
    not)."""
    distinct = n * (1.0 - (1.0 - 1.0 / n) ** width)
    return distinct < 2.0 * n / 3.0


def _encode_winners(encoder: nn.Module, x: Tensor, winner: Tensor) -> Tensor:
    """(B, D) `encoder(x)[b, winner[b, d], d]`, each winning element encoded once, with
    autograd. `winner`: (B, D) int64 element index per row and dimension."""
    b, n, f = x.shape
    d = winner.shape[1]
    flat = winner + torch.arange(b, device=x.device).unsqueeze(1) * n  # (B, D) into B * N
    wins = torch.zeros(b * n, dtype=torch.bool, device=x.device)
    wins[flat.reshape(-1)] = True
    chosen = torch.nonzero(wins).flatten()  # (M,) distinct winners, M <= B * min(N, D)
    slot = torch.empty(b * n, dtype=torch.long, device=x.device)
    slot[chosen] = torch.arange(len(chosen), device=x.device)
    emb = encoder(x.reshape(b * n, f).index_select(0, chosen))  # (M, D)
    pick = slot[flat] * d + torch.arange(d, device=x.device)  # (B, D) into emb.view(-1)
    return emb.reshape(-1)[pick]


def reset_state(state: State, episode_start: Tensor) -> State:
    """Zero the recurrent state of agents whose episode starts.

    Args:
        state: Tensors of shape (B, ...).
        episode_start: (B,) bool.
    """
    batch = state[0].shape[0] if state else episode_start.shape[0]
    if episode_start.shape != (batch,):
        raise ValueError(f"episode_start: expected shape ({batch},), got {tuple(episode_start.shape)}")
    keep = ~episode_start.to(torch.bool)
    return tuple(torch.where(keep.view(-1, *([1] * (s.dim() - 1))), s, torch.zeros_like(s)) for s in state)


# ---------------------------------------------------------------------------------------------
# MultiDiscrete action distribution (section 2.4): independent categoricals, one per dimension.


def middle_prior_bias(nvec: Sequence[int], strength: float) -> Tensor:
    """Initial actor bias that favours the middle choice of every action dimension.

    Choice i of a dimension with n choices gets the logit `-strength * ((i - c) / c) ** 2`,
    c = (n - 1) / 2. In the paper's symmetric tables (section 2.4) the middle choices are zero
    acceleration and zero steering, so the untrained policy mostly keeps its speed and heading
    instead of braking and swerving at random; 0 gives the uniform initial policy.

    Args:
        nvec: Choices per action dimension.
        strength: Logit gap between the middle and the outermost choices (>= 0).

    Returns:
        (sum(nvec),) float32 bias.
    """
    if not strength >= 0:
        raise ValueError(f"action_prior: expected a logit gap >= 0, got {strength!r}")
    parts = []
    for n in nvec:
        c = (n - 1) / 2
        offset = (torch.arange(n, dtype=torch.float32) - c) / max(c, 1.0)
        parts.append(-float(strength) * offset * offset)
    return torch.cat(parts)


def split_logits(logits: Tensor, nvec: Sequence[int]) -> list[Tensor]:
    """Split (..., sum(nvec)) logits into one (..., n_i) tensor per action dimension."""
    if logits.shape[-1] != sum(nvec):
        raise ValueError(f"logits: expected last dimension sum(nvec) = {sum(nvec)}, got {logits.shape[-1]}")
    return list(torch.split(logits, list(nvec), dim=-1))


def sample_actions(
    logits: Tensor, nvec: Sequence[int], deterministic: bool = False, generator: torch.Generator | None = None
) -> Tensor:
    """Draw MultiDiscrete actions.

    Args:
        logits: (..., sum(nvec)) unnormalised log-probabilities.
        nvec: Choices per action dimension.
        deterministic: Take the most likely choice instead of sampling.
        generator: Optional torch generator for reproducible sampling, on the logits' device.

    Returns:
        (..., len(nvec)) int64 actions.
    """
    out = []
    for part in split_logits(logits, nvec):
        if deterministic:
            out.append(part.argmax(dim=-1))
            continue
        probs = torch.softmax(part.float(), dim=-1).reshape(-1, part.shape[-1])
        draw = torch.multinomial(probs, 1, generator=generator).reshape(part.shape[:-1])
        out.append(draw)
    return torch.stack(out, dim=-1)


def log_prob(logits: Tensor, actions: Tensor, nvec: Sequence[int]) -> Tensor:
    """Log-probability of MultiDiscrete actions: the sum over dimensions.

    Args:
        logits: (..., sum(nvec)).
        actions: (..., len(nvec)) integer actions.

    Returns:
        (...) log-probabilities.
    """
    return _sum_log_prob(_log_softmaxes(logits, nvec), actions)


def entropy(logits: Tensor, nvec: Sequence[int]) -> Tensor:
    """Entropy of the MultiDiscrete distribution: the sum of per-dimension entropies, (...)."""
    return _sum_entropy(_log_softmaxes(logits, nvec))


def log_prob_and_entropy(logits: Tensor, actions: Tensor, nvec: Sequence[int]) -> tuple[Tensor, Tensor]:
    """`log_prob(logits, actions, nvec)` and `entropy(logits, nvec)` from one log-softmax per
    action dimension (the PPO loss needs both; the same values)."""
    logps = _log_softmaxes(logits, nvec)
    return _sum_log_prob(logps, actions), _sum_entropy(logps)


def _log_softmaxes(logits: Tensor, nvec: Sequence[int]) -> list[Tensor]:
    return [torch.log_softmax(part, dim=-1) for part in split_logits(logits, nvec)]


def _sum_log_prob(logps: list[Tensor], actions: Tensor) -> Tensor:
    if actions.shape[-1] != len(logps):
        raise ValueError(
            f"actions: expected last dimension len(nvec) = {len(logps)}, got {actions.shape[-1]}"
        )
    total = torch.zeros(logps[0].shape[:-1], dtype=logps[0].dtype, device=logps[0].device)
    for i, logp in enumerate(logps):
        total = total + logp.gather(-1, actions[..., i : i + 1].long()).squeeze(-1)
    return total


def _sum_entropy(logps: list[Tensor]) -> Tensor:
    total = torch.zeros(logps[0].shape[:-1], dtype=logps[0].dtype, device=logps[0].device)
    for logp in logps:
        total = total - (logp.exp() * logp).sum(dim=-1)
    return total


def count_parameters(module: nn.Module) -> int:
    """Number of trainable parameters."""
    return sum(p.numel() for p in module.parameters() if p.requires_grad)
