"""Generalised advantage estimation over agent slots with terminations, truncations and padding.

For a slot that acted at step t (`active[t]`), the one-step TD error is

    delta_t = r_t + gamma * V_next - V(s_t),

with V_next = 0 when the agent was terminated at t (the episode really ended), V_next =
V(final observation) when it was truncated at t (time limit: the future is cut off by the
simulator, not by the task, so the value is bootstrapped), and V_next = V(s_{t+1}) of the same
slot otherwise (the value after the rollout's last step for t = T - 1). The advantage
recursion A_t = delta_t + gamma * lambda * A_{t+1} is cut where the episode ended, and slots
that did not act get A_t = 0, so nothing flows across an autoreset or out of a padded slot.
"""

from __future__ import annotations

from selfplaydrive._optional import requires_extra

with requires_extra("torch"):
    import torch
    from torch import Tensor


def compute_gae(
    rewards: Tensor,
    values: Tensor,
    next_value: Tensor,
    active: Tensor,
    terminated: Tensor,
    truncated: Tensor,
    final_values: Tensor,
    gamma: float,
    gae_lambda: float,
) -> tuple[Tensor, Tensor]:
    """Advantages and returns of one rollout.

    Args:
        rewards: (T, N) reward of each step.
        values: (T, N) V(s_t) from the rollout.
        next_value: (N,) V(s_T), the value of the observation after the last step.
        active: (T, N) bool, the slot acted at step t.
        terminated: (T, N) bool, the agent's episode ended by termination at t.
        truncated: (T, N) bool, ended by truncation at t (termination wins when both are set).
        final_values: (T, N) V(final observation), read where `truncated`.
        gamma: Discount factor in [0, 1].
        gae_lambda: GAE lambda in [0, 1].

    Returns:
        advantages (T, N) and returns = advantages + values (T, N), both 0 where not active.

    Raises:
        ValueError: On mismatched shapes.
    """
    T, N = values.shape
    for name, t in (
        ("rewards", rewards),
        ("active", active),
        ("terminated", terminated),
        ("truncated", truncated),
        ("final_values", final_values),
    ):
        if t.shape != (T, N):
            raise ValueError(f"{name}: expected shape {(T, N)} like values, got {tuple(t.shape)}")
    if next_value.shape != (N,):
        raise ValueError(f"next_value: expected shape {(N,)}, got {tuple(next_value.shape)}")
    term = terminated.bool()
    trunc = truncated.bool() & ~term
    ended = term | trunc
    act = active.to(values.dtype)
    advantages = torch.zeros_like(values)
    last = torch.zeros_like(next_value)
    for t in range(T - 1, -1, -1):
        following = next_value if t == T - 1 else values[t + 1]
        v_next = torch.where(trunc[t], final_values[t], torch.where(term[t], 0.0, following))
        delta = rewards[t] + gamma * v_next - values[t]
        last = (delta + gamma * gae_lambda * (~ended[t]).to(values.dtype) * last) * act[t]
        advantages[t] = last
    returns = (advantages + values) * act
    return advantages, returns
