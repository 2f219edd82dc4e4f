"""Set pooling of the policy models (paper section 3): the Deep Sets max over a set's valid
elements and the pieces that make it fast on the CPU.

- `compact_sets`: drops slots that are padding in every row of a batch (exact, a speed-up).
- `masked_max`: the max pooling with padded elements excluded; the gradient goes to the
  winning element only.
- `encode_max`: `masked_max(encoder(x), valid)` without encoding every element with autograd
  (the winners found first, in cache-sized chunks, then re-encoded); `PoolKernels` holds its
  computations, eager or under `torch.compile`.
- `first_max_index`, `set_amax`, `padding_bias`: the set reductions they are made of, the same
  values as torch's own ops, vectorised where torch's CPU kernels take slow paths.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from selfplaydrive._optional import requires_extra

with requires_extra("torch"):
    import torch
    from torch import Tensor, nn


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
    dimensions (16: 0.18-0.47 ms for a chunk of 16,384 elements, against 0.03-0.05 ms at 32;
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
