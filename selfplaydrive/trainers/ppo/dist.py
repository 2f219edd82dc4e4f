"""Data parallelism through `torchrun` and torch.distributed (nothing home-made).

Under `torchrun --nproc_per_node=K`, every rank builds its own env (seeded `seed + rank` by
the trainer's reset), collects its own rollouts, and wraps the model's sequence evaluation in
`DistributedDataParallel`, which averages gradients over ranks in `backward`. Parameters start
identical (DDP broadcasts rank 0's at construction) and stay identical because every rank
applies the same averaged gradient with the same optimiser and schedule.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

from selfplaydrive._optional import requires_extra

with requires_extra("torch"):
    import torch
    import torch.distributed as td
    from torch import Tensor, nn


@dataclass(frozen=True)
class DistInfo:
    """Rank of this process in the job (0 of 1 without torchrun)."""

    rank: int = 0
    world_size: int = 1
    local_rank: int = 0

    @property
    def enabled(self) -> bool:
        return self.world_size > 1

    @property
    def is_main(self) -> bool:
        return self.rank == 0


def init_distributed() -> DistInfo:
    """Join the process group torchrun describes in the environment (WORLD_SIZE, RANK,
    LOCAL_RANK, MASTER_ADDR/PORT); a plain single process when WORLD_SIZE is unset or 1.
    Backend NCCL with CUDA, else Gloo."""
    world_size = int(os.environ.get("WORLD_SIZE", "1"))
    if world_size <= 1:
        return DistInfo()
    info = DistInfo(int(os.environ["RANK"]), world_size, int(os.environ.get("LOCAL_RANK", "0")))
    if not td.is_initialized():
        backend = "nccl" if torch.cuda.is_available() else "gloo"
        if backend == "nccl":
            torch.cuda.set_device(info.local_rank)
        td.init_process_group(backend=backend)
    return info


def all_reduce_mean(value: Tensor, info: DistInfo) -> Tensor:
    """Mean of a tensor over ranks (the tensor itself when not distributed)."""
    if not info.enabled:
        return value
    out = value.detach().clone()
    td.all_reduce(out, op=td.ReduceOp.SUM)
    return out / info.world_size


class SequenceEvaluator(nn.Module):
    """`forward` = the policy's `forward_sequence`, so DDP (which only hooks `forward`) can
    wrap the BPTT evaluation used in the PPO update."""

    def __init__(self, model: nn.Module) -> None:
        super().__init__()
        self.model = model

    def forward(
        self, obs: Tensor, state: tuple[Tensor, ...], episode_start: Tensor, active: Tensor | None = None
    ) -> tuple[Tensor, Tensor, tuple[Tensor, ...]]:
        if active is None:  # also for models whose forward_sequence has no `active`
            return self.model.forward_sequence(obs, state, episode_start)
        return self.model.forward_sequence(obs, state, episode_start, active=active)


def wrap(model: nn.Module, info: DistInfo, device: torch.device) -> nn.Module:
    """The sequence evaluator, inside DDP when the job has several ranks."""
    evaluator = SequenceEvaluator(model)
    if not info.enabled:
        return evaluator
    ids = [device.index] if device.type == "cuda" else None
    return nn.parallel.DistributedDataParallel(evaluator, device_ids=ids)
