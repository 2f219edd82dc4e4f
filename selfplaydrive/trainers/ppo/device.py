"""Where the trainer runs: its device, a warning about spinning CPU threads, and the opt-in
compilation of a model's set pooling (`PPOConfig.device`, `torch_threads`, `compile`)."""

from __future__ import annotations

import os
import warnings

from selfplaydrive._optional import requires_extra
from selfplaydrive.trainers.ppo.dist import DistInfo

with requires_extra("torch"):
    import torch
    from torch import nn


def resolve_device(name: str, info: DistInfo) -> torch.device:
    """ "auto" -> cuda (cuda:LOCAL_RANK under torchrun) when available, else cpu."""
    if name == "auto":
        name = "cuda" if torch.cuda.is_available() else "cpu"
    if name == "cuda" and info.enabled:
        name = f"cuda:{info.local_rank}"
    if name.startswith("cuda") and not torch.cuda.is_available():
        raise RuntimeError(f"PPOConfig.device = {name!r}, but torch sees no CUDA device")
    return torch.device(name)


def compile_model(model: nn.Module) -> bool:
    """`PPOConfig.compile`: compile the set pooling of `model` (its `compile_pooling`); warns
    and returns False for a model without one."""
    hook = getattr(model, "compile_pooling", None)
    if hook is None:
        warnings.warn(
            f"trainer.compile: {type(model).__name__} has no compiled path (compile_pooling); "
            "training runs eagerly",
            RuntimeWarning,
            stacklevel=3,
        )
        return False
    hook()
    return True


def warn_spinning_threads(device: torch.device) -> None:
    """Warn when several torch CPU threads will spin-wait beside the simulator's.

    The simulator sets `GOMP_SPINCOUNT=20000` (selfplaydrive/_sim) unless `OMP_WAIT_POLICY` is
    set, and torch's OpenMP threads inherit it: idle workers spin about 0.5 ms before sleeping.
    On a loaded 2-core machine, 2 torch threads then trained 37x slower than with
    `OMP_WAIT_POLICY=passive` (159 vs 5,978 agent-steps/s, docs/benchmarks.md, "Trainer"). The
    policy is read when OpenMP loads, before any trainer code runs, so it cannot be changed here.
    """
    if device.type != "cpu" or torch.get_num_threads() < 2 or "OMP_WAIT_POLICY" in os.environ:
        return
    if os.environ.get("GOMP_SPINCOUNT", "0") not in ("", "0"):
        warnings.warn(
            f"{torch.get_num_threads()} torch threads spin-wait (GOMP_SPINCOUNT="
            f"{os.environ['GOMP_SPINCOUNT']}): on a busy machine training can be many times slower; "
            "start the process with OMP_WAIT_POLICY=passive, or use trainer.torch_threads=1",
            RuntimeWarning,
            stacklevel=3,
        )
