"""Wayformer-inspired Transformer policy with FiLM reward conditioning (paper section 3).

Every observed element (the ego, each object, each road segment) becomes a 128-d token through
a modality-specific projection; a FiLM layer scales and shifts every token by functions of the
agent's reward coefficients (section 2.3); an encoder of pre-LayerNorm blocks attends across all
tokens of all modalities, padding masked; a decoder block with a single learned query
cross-attends over the encoder output and feeds the actor (one categorical per action dimension)
and critic heads. The model sees only the current observation (no memory), so its recurrent
state is an empty tuple. At the paper's settings it has 638,229 parameters (docs/models.md).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from selfplaydrive._optional import requires_extra
from selfplaydrive.models.common import (
    ObsSplitter,
    State,
    check_nvec,
    check_positive,
    middle_prior_bias,
    mlp,
    orthogonal_,
)
from selfplaydrive.models.pooling import compact_sets
from selfplaydrive.obs.layout import ObsLayout

with requires_extra("torch"):
    import torch
    from torch import Tensor, nn
    from torch.nn import functional


class Attention(nn.Module):
    """Multi-head attention with a key padding mask.

    Args:
        dim: Token width D.
        num_heads: Heads; must divide `dim`.
    """

    def __init__(self, dim: int, num_heads: int) -> None:
        super().__init__()
        if dim % num_heads:
            raise ValueError(f"num_heads: expected a divisor of the embedding size {dim}, got {num_heads}")
        self.num_heads = num_heads
        self.q = nn.Linear(dim, dim)
        self.kv = nn.Linear(dim, 2 * dim)
        self.out = nn.Linear(dim, dim)

    def forward(self, query: Tensor, keys: Tensor, key_valid: Tensor) -> Tensor:
        """Attend from (B, Nq, D) queries over (B, Nk, D) keys; `key_valid` (B, Nk) bool.

        Every row must have at least one valid key (the ego token guarantees it), otherwise the
        softmax over an empty set would be NaN.
        """
        b, nq, d = query.shape
        h = self.num_heads
        q = self.q(query).view(b, nq, h, d // h).transpose(1, 2)
        k, v = self.kv(keys).view(b, keys.shape[1], 2, h, d // h).permute(2, 0, 3, 1, 4)
        mask = key_valid[:, None, None, :]
        y = functional.scaled_dot_product_attention(q, k, v, attn_mask=mask)
        return self.out(y.transpose(1, 2).reshape(b, nq, d))


class Block(nn.Module):
    """Pre-LayerNorm Transformer block: x + Attn(LN(x), LN(mem)), then x + FFN(LN(x)), ReLU.

    Used as encoder block (self-attention, memory = x) and decoder block (cross-attention).

    Args:
        dim: Token width D.
        num_heads: Attention heads.
        ffn_size: Hidden width of the feed-forward sub-layer.
    """

    def __init__(self, dim: int, num_heads: int, ffn_size: int) -> None:
        super().__init__()
        self.norm_attn = nn.LayerNorm(dim)
        self.attn = Attention(dim, num_heads)
        self.norm_ffn = nn.LayerNorm(dim)
        self.ffn = mlp([dim, ffn_size, dim])

    def forward(self, x: Tensor, memory: Tensor | None, memory_valid: Tensor) -> Tensor:
        """Args: x (B, N, D); memory (B, M, D) or None for self-attention; memory_valid (B, M) bool."""
        y = self.norm_attn(x)
        # Self-attention normalises keys with the same LayerNorm; the decoder receives the
        # encoder output already normalised by the encoder's final LayerNorm.
        x = x + self.attn(y, y if memory is None else memory, memory_valid)
        return x + self.ffn(self.norm_ffn(x))


class TransformerModel(nn.Module):
    """Token encoders, FiLM, Transformer encoder, single-query decoder, actor and critic.

    Args:
        layout: Observation layout of the env (`VecEnv.layout`), or its fields as a mapping.
        action_nvec: Choices per action dimension, e.g. (7, 13).
        embed_size: Token width D (128 in the paper).
        num_heads: Attention heads (4).
        num_encoder_blocks: Encoder depth (2).
        num_decoder_blocks: Decoder depth (1).
        ffn_size: Feed-forward hidden width (512 = 4 D).
        film_hidden: Hidden width of the FiLM MLP on the reward coefficients (128).
        compact: Drop all-padding slots before encoding (exact; faster for sparse scenes).
        action_prior: Initial actor bias towards the middle action choices (zero acceleration
            and steering), as a logit gap (`middle_prior_bias`); 0 starts uniform, as PufferLib.
    """

    is_recurrent = False

    def __init__(
        self,
        layout: ObsLayout | Mapping[str, int],
        action_nvec: Sequence[int] = (7, 13),
        embed_size: int = 128,
        num_heads: int = 4,
        num_encoder_blocks: int = 2,
        num_decoder_blocks: int = 1,
        ffn_size: int = 512,
        film_hidden: int = 128,
        compact: bool = True,
        action_prior: float = 0.0,
    ) -> None:
        super().__init__()
        self.nvec = check_nvec(action_nvec)
        d = self.embed_size = check_positive("embed_size", embed_size)
        check_positive("num_heads", num_heads)
        check_positive("num_encoder_blocks", num_encoder_blocks)
        check_positive("num_decoder_blocks", num_decoder_blocks)
        check_positive("ffn_size", ffn_size)
        check_positive("film_hidden", film_hidden)
        self.compact = compact
        self.splitter = s = ObsSplitter(layout)
        if s.coef_in == 0:
            raise ValueError("layout: the FiLM layer needs ego features named coef_*, found none")
        self.ego_proj = nn.Linear(s.ego_in, d)
        self.object_proj = nn.Linear(s.object_in, d)
        self.road_proj = nn.Linear(s.road_in, d)
        # Learned modality embeddings (ego, object, road) added to the tokens, as in Wayformer.
        self.modality = nn.Parameter(torch.zeros(3, d))
        self.film = mlp([s.coef_in, film_hidden, 2 * d])
        self.encoder = nn.ModuleList(Block(d, num_heads, ffn_size) for _ in range(num_encoder_blocks))
        self.encoder_norm = nn.LayerNorm(d)
        self.query = nn.Parameter(torch.zeros(1, 1, d))
        self.decoder = nn.ModuleList(Block(d, num_heads, ffn_size) for _ in range(num_decoder_blocks))
        self.decoder_norm = nn.LayerNorm(d)
        self.actor = nn.Linear(d, sum(self.nvec))
        self.critic = nn.Linear(d, 1)
        self._init_weights()
        with torch.no_grad():
            self.actor.bias.copy_(middle_prior_bias(self.nvec, action_prior))

    def _init_weights(self) -> None:
        nn.init.normal_(self.modality, std=0.02)
        nn.init.normal_(self.query, std=0.02)
        # FiLM starts as the identity (gamma = 1 + 0, beta = 0) so conditioning is learned
        # gradually rather than scrambling tokens at initialisation.
        nn.init.zeros_(self.film[-1].weight)
        nn.init.zeros_(self.film[-1].bias)
        orthogonal_(self.actor.weight, 0.01)
        nn.init.zeros_(self.actor.bias)

    def initial_state(self, batch_size: int, device: torch.device | str | None = None) -> State:
        """The feed-forward model keeps no state: an empty tuple."""
        return ()

    def tokens(self, obs: Tensor) -> tuple[Tensor, Tensor]:
        """FiLM-modulated tokens and their validity.

        Args:
            obs: (B, obs_dim).

        Returns:
            tokens (B, 1 + O', D) and valid (B, 1 + O') bool, ego first; O' = objects + road
            slots kept (all of them unless `compact`).
        """
        parts = self.splitter(obs)
        objects, obj_valid = parts["objects"], parts["object_valid"]
        road, road_valid = parts["road"], parts["road_valid"]
        if self.compact:
            objects, obj_valid = compact_sets(objects, obj_valid)
            road, road_valid = compact_sets(road, road_valid)
        ego = (self.ego_proj(parts["ego"]) + self.modality[0]).unsqueeze(1)
        obj = self.object_proj(objects) + self.modality[1]
        rd = self.road_proj(road) + self.modality[2]
        x = torch.cat([ego, obj, rd], dim=1)
        gamma, beta = self.film(parts["coef"]).unsqueeze(1).chunk(2, dim=-1)
        x = x * (1.0 + gamma) + beta
        ego_valid = obj_valid.new_ones(obj_valid.shape[0], 1)  # also for a layout without objects
        return x, torch.cat([ego_valid, obj_valid, road_valid], dim=1)

    def embed(self, obs: Tensor) -> Tensor:
        """Decoder output for (B, obs_dim) observations: (B, D)."""
        x, valid = self.tokens(obs)
        for block in self.encoder:
            x = block(x, None, valid)
        memory = self.encoder_norm(x)
        q = self.query.expand(x.shape[0], -1, -1)
        for block in self.decoder:
            q = block(q, memory, valid)
        return self.decoder_norm(q.squeeze(1))

    def forward(
        self, obs: Tensor, state: State = (), episode_start: Tensor | None = None
    ) -> tuple[Tensor, Tensor, State]:
        """One step for a batch of agents (same interface as `DeepSetsModel.forward`).

        Args:
            obs: (B, obs_dim).
            state: Ignored (the model is feed-forward); pass `initial_state(...)`.
            episode_start: Ignored.

        Returns:
            logits (B, sum(nvec)), value (B,), the empty state.
        """
        z = self.embed(obs)
        return self.actor(z), self.critic(z).squeeze(-1), ()

    def forward_sequence(
        self,
        obs: Tensor,
        state: State = (),
        episode_start: Tensor | None = None,
        active: Tensor | None = None,
    ) -> tuple[Tensor, Tensor, State]:
        """Evaluate (T, B, obs_dim) observations; returns (T, B, sum(nvec)), (T, B), ().

        `active` ((T, B) bool, optional): only those entries are evaluated; the others get
        zero logits and values (PPO gives them no loss, `DeepSetsModel.forward_sequence`).
        """
        if obs.dim() != 3:
            raise ValueError(f"obs: expected (T, B, obs_dim), got {tuple(obs.shape)}")
        t_len, b = obs.shape[:2]
        flat = obs.reshape(t_len * b, -1)
        if active is None:
            logits, value, _ = self.forward(flat)
            return logits.reshape(t_len, b, -1), value.reshape(t_len, b), ()
        if active.shape != obs.shape[:2]:
            raise ValueError(f"active: expected shape {tuple(obs.shape[:2])}, got {tuple(active.shape)}")
        rows = torch.nonzero(active.reshape(-1)).flatten()
        logits = flat.new_zeros(t_len * b, sum(self.nvec))
        value = flat.new_zeros(t_len * b)
        if len(rows):  # float32 outputs; the parts are bf16 under autocast on CUDA
            part_logits, part_value, _ = self.forward(flat.index_select(0, rows))
            logits = logits.index_copy(0, rows, part_logits.float())
            value = value.index_copy(0, rows, part_value.float())
        return logits.reshape(t_len, b, -1), value.reshape(t_len, b), ()
