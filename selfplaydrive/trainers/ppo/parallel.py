"""Minibatch parts on several threads (`PPOConfig.update_threads`).

On a CPU the update's ops are small (0.1-1 ms; docs/benchmarks.md, "Trainer"), so torch's
intra-op threads gain little: most ops are below its parallel grain, and a spinning pool
collapses on a busy machine. Here the parallelism is one level up. A minibatch's agent slots
are cut into parts; part 0 runs forward and backward on the model in the calling thread while
part k > 0 runs on replica k in a pool thread (torch's ops release the GIL, and each thread runs
its ops itself with one intra-op thread). Each part's loss is divided by the whole minibatch's
count of active entries and normalises advantages by the whole minibatch's statistics
(`PPOTrainer.minibatch_step`), so the parts' gradients add up to the minibatch's gradient:
the same update up to float rounding. The replicas take the model's weights before every
minibatch and their gradients are added in a fixed order, so a seed gives the same run at any
timing of the threads.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor

from selfplaydrive._optional import requires_extra
from selfplaydrive.trainers.ppo.dist import SequenceEvaluator

with requires_extra("torch"):
    import torch
    from torch import Tensor, nn

# (slots, sequence evaluator, whole-minibatch statistics) -> (loss, diagnostics)
PartLoss = Callable[[Tensor, nn.Module, object], tuple[Tensor, dict[str, Tensor]]]


class PartWorkers:
    """Replicas of `model` and one pool thread per replica.

    Args:
        model: The trained model; its replicas are deep copies whose weights `sync` refreshes.
        extra: Parts beyond the calling thread's (update_threads - 1).
        part_loss: Loss of a part (`PPOTrainer.minibatch_loss`).
    """

    def __init__(self, model: nn.Module, extra: int, part_loss: PartLoss) -> None:
        self.replicas = [copy.deepcopy(model) for _ in range(extra)]
        self._evaluators = [SequenceEvaluator(r) for r in self.replicas]
        self._params = [list(r.parameters()) for r in self.replicas]
        self._loss = part_loss
        self._pool = ThreadPoolExecutor(extra, thread_name_prefix="spd-update")

    def sync(self, model: nn.Module) -> None:
        """Copy `model`'s weights into every replica (before a minibatch)."""
        src = [p.detach() for p in model.parameters()]
        with torch.no_grad():
            for params in self._params:
                torch._foreach_copy_(params, src)

    def submit(self, k: int, slots: Tensor, whole: object) -> Future[dict[str, Tensor]]:
        """Forward and backward of part `slots` on replica `k` in the pool; the future holds
        the part's diagnostics, or raises its exception."""

        def run() -> dict[str, Tensor]:
            loss, info = self._loss(slots, self._evaluators[k], whole)
            loss.backward()
            return info

        return self._pool.submit(run)

    def add_gradients(self, model: nn.Module) -> None:
        """Add the replicas' gradients to `model`'s, replica by replica in order, and clear
        theirs."""
        with torch.no_grad():
            for params in self._params:
                for p, q in zip(model.parameters(), params, strict=True):
                    if q.grad is None:  # unused by that part
                        continue
                    if p.grad is None:
                        p.grad = q.grad
                    else:
                        p.grad.add_(q.grad)
                    q.grad = None


def balanced_parts(slots: Tensor, active: Tensor, parts: int) -> list[Tensor]:
    """`slots` dealt into `parts` parts of (nearly) equal size and equal active entries
    (`active`: each slot's count): sorted by it (stable), then dealt round-robin. The encoders'
    work follows the active entries, the LSTM's the slots; the slowest part sets the pace."""
    order = slots[torch.sort(active, descending=True, stable=True).indices]
    return [order[k::parts] for k in range(parts)]
