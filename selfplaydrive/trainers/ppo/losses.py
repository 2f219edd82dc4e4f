"""PPO-clip losses over masked entries (inactive agent slots contribute nothing).

Every loss is a masked mean: sum(x * mask) / max(sum(mask), 1), so the padding share of a
minibatch changes neither the loss scale nor the gradient of real entries.
"""

from __future__ import annotations

from selfplaydrive._optional import requires_extra

with requires_extra("torch"):
    import torch
    from torch import Tensor


def masked_mean(x: Tensor, mask: Tensor) -> Tensor:
    """Mean of `x` over entries where `mask` is True (0 when there is none)."""
    m = mask.to(x.dtype)
    return (x * m).sum() / m.sum().clamp_min(1.0)


def normalize_advantages(adv: Tensor, mask: Tensor, eps: float = 1e-8) -> Tensor:
    """Zero mean, unit std over the masked entries; masked-out entries become 0."""
    mean = masked_mean(adv, mask)
    var = masked_mean((adv - mean) ** 2, mask)
    return torch.where(mask, (adv - mean) / (var.sqrt() + eps), torch.zeros_like(adv))


def policy_loss(
    new_logprob: Tensor, old_logprob: Tensor, advantages: Tensor, mask: Tensor, clip_coef: float
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
    loss = masked_mean(torch.maximum(unclipped, clipped), mask)
    with torch.no_grad():
        info = {
            "approx_kl": masked_mean((ratio - 1.0) - log_ratio, mask),
            "clip_fraction": masked_mean(((ratio - 1.0).abs() > clip_coef).float(), mask),
        }
    return loss, info


def value_loss(
    new_value: Tensor,
    old_value: Tensor,
    returns: Tensor,
    mask: Tensor,
    clip: bool,
    clip_coef: float,
) -> Tensor:
    """0.5 * squared error to the returns; with `clip`, the larger of the errors of the new
    value and of the old value moved by at most `clip_coef` towards the new one."""
    err = (new_value - returns) ** 2
    if clip:
        moved = old_value + (new_value - old_value).clamp(-clip_coef, clip_coef)
        err = torch.maximum(err, (moved - returns) ** 2)
    return 0.5 * masked_mean(err, mask)
