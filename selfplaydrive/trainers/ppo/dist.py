"""Data parallelism through `torchrun` and torch.distributed (nothing home-made).

Under `torchrun --nproc_per_node=K`, every rank builds its own env (seeded `seed + rank` by
the trainer's reset), collects its own rollouts, and wraps the model's sequence evaluation in
`DistributedDataParallel`, which averages gradients over ranks in `backward`. Parameters start
identical (DDP broadcasts rank 0's at construction) and stay identical because every rank
applies the same averaged gradient with the same optimiser and schedule.

On several machines (`torchrun --nnodes=M`, docs/training.md "Several machines") nothing
changes but the rank numbers; a resumed job checks that every rank loaded a checkpoint of the
same update (`check_resume_agrees`).
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass

from selfplaydrive._optional import requires_extra
from selfplaydrive.errors import CheckpointError
from selfplaydrive.trainers.ppo.checkpoint import checkpoint_name

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


def exit_distributed(status: int) -> None:
    """End a process that joined a torchrun process group with `status`, skipping the
    interpreter's teardown; return (doing nothing) in a process that joined none.

    Gloo's worker threads release the last collectives' tensors after the caller has moved on.
    One still doing so while the interpreter finalizes takes the GIL from a dying runtime and
    aborts the process ("terminate called without an active exception", SIGABRT), so a rank
    whose files are all written could still be reported failed (seen in about 1 run in 4 of
    tests/trainers/test_ddp.py on 2 cores). Call this once the run's outputs are closed.
    """
    if not (td.is_available() and td.is_initialized()):
        return
    td.destroy_process_group()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)


def all_reduce_mean(value: Tensor, info: DistInfo) -> Tensor:
    """Mean of a tensor over ranks (the tensor itself when not distributed)."""
    if not info.enabled:
        return value
    out = value.detach().clone()
    td.all_reduce(out, op=td.ReduceOp.SUM)
    return out / info.world_size


def check_resume_agrees(update: int, checkpoint: str | os.PathLike[str], info: DistInfo) -> None:
    """Fail on every rank when the ranks of a resumed job loaded checkpoints of different updates.

    Every rank resumes from its own file, the newest it finds; a node stopped between the
    ranks' saves leaves the newest update to some ranks only. Resumed anyway, the ranks would
    count different updates with different parameters (DDP broadcasts only at construction,
    before the load), write mismatched checkpoints and end at different times.

    Args:
        update: Updates done in the checkpoint this rank loaded.
        checkpoint: That checkpoint (named in the error).
        info: This process's rank; a single process always agrees.

    Raises:
        CheckpointError: On every rank, listing each rank's update and naming the file of the
            oldest one, which every rank is likely to still have.
    """
    if not info.enabled:
        return
    updates = [0] * info.world_size
    td.all_gather_object(updates, int(update))
    if len(set(updates)) == 1:
        return
    listed = ", ".join(f"rank {r} update {u}" for r, u in enumerate(updates))
    oldest = checkpoint_name(min(updates))
    raise CheckpointError(
        f"resume: the ranks loaded checkpoints of different updates ({listed}), as when a node "
        f"stopped between the ranks' saves; resume every rank from the same update, e.g. "
        f"resume=<run folder>/checkpoints/{oldest} (each rank reads its own .rank<r> sibling)",
        checkpoint,
    )


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
