"""Reward scaling by the running spread of the discounted return (`PPOConfig.norm_returns`).

Every reward of a rollout is divided by sigma, the standard deviation of the discounted return
R_t = gamma R_{t-1} + r_t of each agent slot, estimated over all active entries seen so far
(R restarts at 0 where an agent's episode starts). The mean is not subtracted: a shift would
change which of "keep going" and "end here" pays more. This keeps the value targets near unit
scale whatever the reward's weights (the main job's waypoint reward is 4x the paper's), so that
`value_clip_coef` and `max_grad_norm` mean the same for every reward setting. It is the reward
scaling studied by Engstrom et al. (2020, "Implementation Matters in Deep RL") and what
stable-baselines3's `VecNormalize(norm_reward=True)` does, here over a whole rollout at once.

Logged returns and the evaluation are unaffected: they read the env's own rewards.
"""

from __future__ import annotations

from selfplaydrive._optional import requires_extra
from selfplaydrive.trainers.ppo.dist import DistInfo

with requires_extra("torch"):
    import torch
    import torch.distributed as td
    from torch import Tensor


class ReturnScaler:
    """Running second moment of the discounted return, and rewards divided by its spread.

    Args:
        num_slots: N, agent slots of the env (one running return each).
        gamma: Discount factor of the return (the trainer's `gamma`).
        device: Where the per-slot returns live (the rollout's device).
        eps: Added to the variance before the square root, so that the first rollouts (all
            rewards 0, say) divide by a finite number.

    Attributes:
        running: (N,) float64 discounted return of each slot at the end of the last rollout.
        count: Active entries seen, over all ranks.
        mean: Mean of the returns seen (float).
        m2: Sum of squared deviations from `mean` (float; variance = m2 / count).
    """

    def __init__(self, num_slots: int, gamma: float, device: torch.device, eps: float = 1e-8) -> None:
        self.gamma, self.eps = gamma, eps
        self.running = torch.zeros(num_slots, dtype=torch.float64, device=device)
        self.count, self.mean, self.m2 = 0.0, 0.0, 0.0

    @property
    def std(self) -> float:
        """Current spread sigma of the return (1 before any entry was seen)."""
        if self.count < 2:
            return 1.0
        return float((self.m2 / self.count + self.eps) ** 0.5)

    @torch.no_grad()
    def scale(
        self, rewards: Tensor, active: Tensor, episode_start: Tensor, dist: DistInfo | None = None
    ) -> Tensor:
        """Fold one rollout into the statistics and return its rewards divided by sigma.

        Args:
            rewards: (T, N) float32 rewards (0 where the slot did not act).
            active: (T, N) bool, the slot acted at step t.
            episode_start: (T, N) bool, the agent's episode starts at step t.
            dist: Under torchrun, the entries of every rank are pooled (all-reduce of count,
                sum and sum of squares), so that every rank divides by the same sigma.

        Returns:
            (T, N) float32 rewards / sigma, sigma updated with this rollout's returns.
        """
        t_len = rewards.shape[0]
        ret = self.running
        seen = torch.empty(rewards.shape, dtype=torch.float64, device=rewards.device)
        for t in range(t_len):
            fresh = ret.masked_fill(episode_start[t], 0.0)
            ret = torch.where(active[t], self.gamma * fresh + rewards[t].double(), ret)
            seen[t] = ret
        self.running = ret
        values = seen[active]
        stats = torch.stack([values.new_tensor(float(values.numel())), values.sum(), (values * values).sum()])
        if dist is not None and dist.enabled:
            td.all_reduce(stats, op=td.ReduceOp.SUM)
        self._merge(*(float(x) for x in stats))
        return rewards / self.std

    def _merge(self, n: float, total: float, squares: float) -> None:
        """Chan et al.'s pairwise update of (count, mean, m2) with a batch's moments."""
        if n == 0:
            return
        b_mean = total / n
        b_m2 = max(squares - n * b_mean * b_mean, 0.0)
        count = self.count + n
        delta = b_mean - self.mean
        self.m2 += b_m2 + delta * delta * self.count * n / count
        self.mean += delta * n / count
        self.count = count

    def state_dict(self) -> dict[str, object]:
        return {"running": self.running.cpu(), "count": self.count, "mean": self.mean, "m2": self.m2}

    def load_state_dict(self, state: dict[str, object]) -> None:
        self.running = state["running"].to(self.running.device, torch.float64)
        self.count, self.mean, self.m2 = state["count"], state["mean"], state["m2"]
