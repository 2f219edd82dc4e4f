"""Deep Sets + LSTM policy (paper section 3, PufferDrive's default model).

Each modality is embedded by its own small MLP (per element for the object and road sets),
each set is collapsed by an element-wise maximum over its valid elements, the three vectors are
concatenated and fed to an MLP, an LSTM, and linear actor (one categorical per action
dimension) and critic heads. At the paper's settings (64-d inputs, LSTM of 256) it has 596,757
parameters; docs/models.md gives the arithmetic.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from itertools import pairwise

from selfplaydrive._optional import requires_extra
from selfplaydrive.models.common import (
    ObsSplitter,
    State,
    check_nvec,
    check_positive,
    middle_prior_bias,
    orthogonal_,
    reset_state,
)
from selfplaydrive.models.pooling import EAGER_POOLING, PoolKernels, compact_sets, encode_max
from selfplaydrive.obs.layout import ObsLayout

with requires_extra("torch"):
    import torch
    from torch import Tensor, nn


class _InputLinear(nn.Linear):
    """`nn.Linear` (same parameters and values) whose weight gradient is computed as
    (x^T g)^T rather than g^T x: with a handful of input features torch's CPU product for the
    latter is slow (the laptop object encoder, 8,736 rows x 9 features: 0.99 -> 0.35 ms for
    forward + backward; docs/benchmarks.md, "Trainer")."""

    def forward(self, x: Tensor) -> Tensor:
        # a contiguous (in, out) copy of the weight makes autograd's product for its gradient
        # x^T g, and the transpose hands it back as (out, in)
        flat = torch.addmm(self.bias, x.reshape(-1, self.in_features), self.weight.t().contiguous())
        return flat.reshape(*x.shape[:-1], self.out_features)


def _encoder(in_dim: int, width: int) -> nn.Sequential:
    # PufferDrive's encoder is Linear -> LayerNorm -> Linear; the GELU after the norm makes it an
    # MLP proper (no parameters, so the count is unchanged).
    return nn.Sequential(_InputLinear(in_dim, width), nn.LayerNorm(width), nn.GELU(), nn.Linear(width, width))


def _lstm_step(lstm: nn.LSTM, x: Tensor, h: Tensor, c: Tensor) -> tuple[Tensor, Tensor]:
    """One step of the one-layer `lstm` for (B, in) inputs: the fused cell on the same weights.
    `nn.LSTM` goes through oneDNN, which sets up a primitive for every new batch size, and the
    number of acting agents changes every step (docs/benchmarks.md, "Trainer"); the values
    agree up to float rounding. Float32 under autocast too, like `_lstm_sequence`."""
    with torch.autocast(device_type=x.device.type, enabled=False):
        return torch.lstm_cell(
            x.float(), (h, c), lstm.weight_ih_l0, lstm.weight_hh_l0, lstm.bias_ih_l0, lstm.bias_hh_l0
        )


def _lstm_sequence(lstm: nn.LSTM, x: Tensor, h: Tensor, c: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """`lstm` over (T, B, in) inputs from (B, hidden) states: outputs (T, B, hidden), h, c.

    The recurrence runs in float32 even under bf16 autocast (`PPOConfig.precision`): the state
    carries across a whole rollout, where bf16 rounding would compound, and cuDNN's bf16 RNN
    support depends on its version; the LSTM is a small share of the model's work."""
    with torch.autocast(device_type=x.device.type, enabled=False):
        out, (h1, c1) = lstm(x.float(), (h.unsqueeze(0), c.unsqueeze(0)))
    return out, h1.squeeze(0), c1.squeeze(0)


def _orthogonal(module: nn.Module, gain: float) -> None:
    for name, p in module.named_parameters():
        if p.dim() >= 2:
            orthogonal_(p, gain)
        elif "bias" in name and not isinstance(module, nn.LayerNorm):
            nn.init.zeros_(p)


class DeepSetsModel(nn.Module):
    """Per-modality encoders, masked max pooling, MLP, LSTM, actor and critic heads.

    Args:
        layout: Observation layout of the env (`VecEnv.layout`), or its fields as a mapping.
        action_nvec: Choices per action dimension, e.g. (7, 13) for acceleration x steering.
        input_size: Width of every modality embedding (64 in the paper).
        hidden_size: Width of the shared MLP output, the LSTM input (256).
        lstm_size: LSTM hidden size (256).
        compact: Drop all-padding slots before encoding (exact; faster for sparse scenes).
        action_prior: Initial actor bias towards the middle action choices (zero acceleration
            and steering), as a logit gap (`middle_prior_bias`); 0 starts uniform, as PufferLib.
    """

    is_recurrent = True

    def __init__(
        self,
        layout: ObsLayout | Mapping[str, int],
        action_nvec: Sequence[int] = (7, 13),
        input_size: int = 64,
        hidden_size: int = 256,
        lstm_size: int = 256,
        compact: bool = True,
        action_prior: float = 0.0,
    ) -> None:
        super().__init__()
        self.nvec = check_nvec(action_nvec)
        self.input_size = check_positive("input_size", input_size)
        self.hidden_size = check_positive("hidden_size", hidden_size)
        self.lstm_size = check_positive("lstm_size", lstm_size)
        self.compact = compact
        self.splitter = ObsSplitter(layout)
        s = self.splitter
        self.ego_encoder = _encoder(s.ego_in, input_size)
        self.object_encoder = _encoder(s.object_in, input_size)
        self.road_encoder = _encoder(s.road_in, input_size)
        self.shared = nn.Sequential(nn.GELU(), nn.Linear(3 * input_size, hidden_size), nn.ReLU())
        self.lstm = nn.LSTM(hidden_size, lstm_size)
        self.actor = nn.Linear(lstm_size, sum(self.nvec))
        self.critic = nn.Linear(lstm_size, 1)
        self._init_weights()
        with torch.no_grad():
            self.actor.bias.copy_(middle_prior_bias(self.nvec, action_prior))
        self.pool_kernels = EAGER_POOLING

    def compile_pooling(self) -> None:
        """Run the object and road encoders with their max pooling under `torch.compile`
        (`PoolKernels.compiled`; `PPOConfig.compile`). Same parameters and values up to float
        rounding; the first calls compile (seconds each)."""
        self.pool_kernels = PoolKernels.compiled()

    def _init_weights(self) -> None:
        # PufferLib-style init: orthogonal sqrt(2) trunk, small actor (near-uniform initial policy),
        # unit-gain critic, zero biases.
        for m in (self.ego_encoder, self.object_encoder, self.road_encoder, self.shared):
            _orthogonal(m, math.sqrt(2))
        _orthogonal(self.lstm, 1.0)
        _orthogonal(self.actor, 0.01)
        _orthogonal(self.critic, 1.0)

    def initial_state(self, batch_size: int, device: torch.device | str | None = None) -> State:
        """Zero LSTM state: (h, c), each (batch_size, lstm_size)."""
        h = torch.zeros(batch_size, self.lstm_size, device=device)
        return (h, h.clone())

    def encode(self, obs: Tensor) -> Tensor:
        """Observation embedding before the LSTM.

        Args:
            obs: (B, obs_dim) flat observations.

        Returns:
            (B, hidden_size).
        """
        parts = self.splitter(obs)
        objects, obj_valid = parts["objects"], parts["object_valid"]
        road, road_valid = parts["road"], parts["road_valid"]
        if self.compact:
            objects, obj_valid = compact_sets(objects, obj_valid)
            road, road_valid = compact_sets(road, road_valid)
        ego = self.ego_encoder(parts["ego"])
        obj = self._pool(self.object_encoder, objects, obj_valid, ego)
        rd = self._pool(self.road_encoder, road, road_valid, ego)
        return self.shared(torch.cat([ego, obj, rd], dim=1))

    def _pool(self, encoder: nn.Module, x: Tensor, valid: Tensor, ego: Tensor) -> Tensor:
        """Max-pooled embedding of one set; zeros for a block the encoder's layout leaves empty
        (e.g. an encoder without road rows, obs/encoders.py)."""
        if x.shape[1] == 0:
            return ego.new_zeros(ego.shape[0], self.input_size)
        return encode_max(encoder, x, valid, self.input_size, self.pool_kernels)

    def forward(self, obs: Tensor, state: State, episode_start: Tensor) -> tuple[Tensor, Tensor, State]:
        """One step for a batch of agents.

        Args:
            obs: (B, obs_dim) observations.
            state: (h, c) from `initial_state` or the previous call, each (B, lstm_size).
            episode_start: (B,) bool; True resets that agent's state before this step.

        Returns:
            logits (B, sum(nvec)), value (B,), new state (h, c).
        """
        self._check_state(state, obs.shape[0])
        h, c = reset_state(state, episode_start)
        h, c = _lstm_step(self.lstm, self.encode(obs), h, c)
        return self.actor(h), self.critic(h).squeeze(-1), (h, c)

    def forward_sequence(
        self, obs: Tensor, state: State, episode_start: Tensor, active: Tensor | None = None
    ) -> tuple[Tensor, Tensor, State]:
        """Evaluate a rollout segment for PPO with truncated BPTT.

        The encoder runs on all T*B observations at once (only the `active` ones when given);
        the LSTM runs over chunks between the times at which some agent's episode starts,
        resetting those agents' state there. Without `active` the result equals T calls of
        `forward`.

        Args:
            obs: (T, B, obs_dim).
            state: (h, c) at the start of the segment, each (B, lstm_size).
            episode_start: (T, B) bool.
            active: Optional (T, B) bool, the entries whose outputs are used. The others are
                not encoded (the LSTM sees a zero embedding there), so their outputs, and the
                state after them, are meaningless. Exact for PPO, where such entries carry no
                loss and an agent's next active entry starts its episode (state reset); with a
                third of the slots acting this skips two thirds of the encoder's work.

        Returns:
            logits (T, B, sum(nvec)), values (T, B), state after the last step.
        """
        if obs.dim() != 3 or episode_start.shape != obs.shape[:2]:
            raise ValueError(
                f"obs, episode_start: expected (T, B, obs_dim) and (T, B), "
                f"got {tuple(obs.shape)} and {tuple(episode_start.shape)}"
            )
        t_len, b = obs.shape[:2]
        self._check_state(state, b)
        x = self._encode_rows(obs.reshape(t_len * b, -1), active).reshape(t_len, b, -1)
        starts = episode_start.to(torch.bool)
        bounds = [0, *[t for t in torch.nonzero(starts[1:].any(dim=1)).flatten().add(1).tolist()], t_len]
        h, c = state
        outs = []
        for lo, hi in pairwise(bounds):
            h, c = reset_state((h, c), starts[lo])
            out, h, c = _lstm_sequence(self.lstm, x[lo:hi], h, c)
            outs.append(out)
        out = torch.cat(outs, dim=0)
        return self.actor(out), self.critic(out).squeeze(-1), (h, c)

    def _encode_rows(self, obs: Tensor, active: Tensor | None) -> Tensor:
        """`encode` of the rows of (N, obs_dim) `obs` where `active` ((..., ) bool, N entries)
        is set, zeros elsewhere; all rows when `active` is None."""
        if active is None:
            return self.encode(obs)
        if active.numel() != obs.shape[0]:
            raise ValueError(
                f"active: expected {obs.shape[0]} entries like obs, got shape {tuple(active.shape)}"
            )
        rows = torch.nonzero(active.reshape(-1)).flatten()
        if not len(rows):
            return obs.new_zeros(obs.shape[0], self.hidden_size)
        part = self.encode(obs.index_select(0, rows))  # bf16 under autocast on CUDA
        return part.new_zeros(obs.shape[0], self.hidden_size).index_copy(0, rows, part)

    def _check_state(self, state: State, batch: int) -> None:
        if len(state) != 2 or any(s.shape != (batch, self.lstm_size) for s in state):
            shapes = [tuple(s.shape) for s in state]
            raise ValueError(
                f"state: expected (h, c) of shape ({batch}, {self.lstm_size}) each, got {shapes}"
            )
