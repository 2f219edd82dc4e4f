"""PPO-clip losses over masked entries (inactive agent slots contribute nothing).

Every loss is a masked mean: sum(x * mask) / max(sum(mask), 1), so the padding share of a
minibatch changes neither the loss scale nor the gradient of real entries. `count` replaces
the denominator, so that the losses of the parts of a minibatch, each over its own entries and
divided by the whole minibatch's count, add up to the whole minibatch's loss
(`PPOConfig.update_threads`).
"""

from __future__ import annotations

from selfplaydrive._optional import requires_extra

with requires_extra("torch"):
    import torch
    from torch import Tensor


def masked_mean(x: Tensor, mask: Tensor, count: Tensor | None = None) -> Tensor:
    """Mean of `x` over entries where `mask` is True (0 when there is none); divided by
    `count` instead of the number of those entries when given."""
    m = mask.to(x.dtype)
    return (x * m).sum() / (m.sum() if count is None else count).clamp_min(1.0)


def advantage_stats(adv: Tensor, mask: Tensor, eps: float = 1e-8) -> tuple[Tensor, Tensor]:
    """Mean and std + eps of the masked entries, as `normalize_advantages` uses them."""
    mean = masked_mean(adv, mask)
    var = masked_mean((adv - mean) ** 2, mask)
    return mean, var.sqrt() + eps


def normalize_advantages(
    adv: Tensor, mask: Tensor, eps: float = 1e-8, stats: tuple[Tensor, Tensor] | None = None
) -> Tensor:
    """Zero mean, unit std over the masked entries (or by the given `advantage_stats`, e.g.
    those of a whole minibatch for one of its parts); masked-out entries become 0."""
    mean, scale = advantage_stats(adv, mask, eps) if stats is None else stats
    return torch.where(mask, (adv - mean) / scale, torch.zeros_like(adv))


def policy_loss(
    new_logprob: Tensor,
    old_logprob: Tensor,
    advantages: Tensor,
    mask: Tensor,
    clip_coef: float,
    count: Tensor | None = None,
) -> tuple[Tensor, dict[str, Tensor]]:
    """Clipped surrogate: mean of max(-A r, -A clip(r, 1 - eps, 1 + eps)), r = exp(new - old).

    Returns:
        The loss (scalar) and diagnostics: approx_kl ((r - 1) - log r, the low-variance
        estimator), clip_fraction (share of entries with |r - 1| > eps).
    """
    log_ratio = new_logprob - old_logprob
    ratio = log_ratio.exp()
    unclipped = -advantages * ratio
    clipped = -advantages * ratio.clamp(1.0 - clip_coef, 1.0 + clip_coef)
    loss = masked_mean(torch.maximum(unclipped, clipped), mask, count)
    with torch.no_grad():
        info = {
            "approx_kl": masked_mean((ratio - 1.0) - log_ratio, mask, count),
            "clip_fraction": masked_mean(((ratio - 1.0).abs() > clip_coef).float(), mask, count),
        }
    return loss, info


def value_loss(
    new_value: Tensor,
    old_value: Tensor,
    returns: Tensor,
    mask: Tensor,
    clip: bool,
    clip_coef: float,
    count: Tensor | None = None,
) -> Tensor:
    """0.5 * squared error to the returns; with `clip`, the larger of the errors of the new
    value and of the old value moved by at most `clip_coef` towards the new one."""
    err = (new_value - returns) ** 2
    if clip:
        moved = old_value + (new_value - old_value).clamp(-clip_coef, clip_coef)
        err = torch.maximum(err, (moved - returns) ** 2)
    return 0.5 * masked_mean(err, mask, count)
