"""Pieces shared by the policy models (paper section 3).

- `ObsSplitter`: cuts a flat (B, obs_dim) observation into per-modality tensors using the
  env's `ObsLayout`, so no model hard-codes column offsets.
- The set pooling (`masked_max`, `encode_max`, `compact_sets`) is in `models/pooling.py`.
- MultiDiscrete helpers: split logits, sample, log-probability and entropy summed over the
  action dimensions (acceleration x steering by default, section 2.4).
- `check_nvec`, `mlp`: argument checking and small builders.

Every model returns, for a batch of B observations, concatenated logits (B, sum(nvec)), a
value (B,) and a recurrent state: a tuple of tensors (empty for feed-forward models).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import fields
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
