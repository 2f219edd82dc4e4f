"""Overlapped collection (`PPOConfig.overlap_collection`): the next rollout is collected in a
second thread while the current one trains.

On a CPU the update runs on one core (small ops, one torch thread: docs/benchmarks.md,
"Trainer") and collection (env step and inference) is about a fifth of an update's time, so a
second core would otherwise stay idle. Both sides release the GIL in their heavy parts: the
simulator steps `nogil`, and torch's ops drop it while they run.

The schedule is fixed, whatever the threads' timing: when update k starts its last epoch, the
policy's weights of that moment are copied into the *actor*, which collects rollout k+1 while
the epoch runs (the collection, about a fifth of an update, fits in one epoch of three). So the
data of an update comes from weights one epoch behind the update's start, and a seed gives the
same run every time. Starting at the update's start instead (a whole update behind) hid the
collection just as well but learnt less per step in the main job (docs/training.md, "Speed").
"""

from __future__ import annotations

import copy
import threading
import time
from collections.abc import Callable

from selfplaydrive._optional import requires_extra

with requires_extra("torch"):
    from torch import nn


def make_actor(model: nn.Module) -> nn.Module:
    """A copy of `model` that acts while `model` trains: no gradients, weights set with
    `load_state_dict(model.state_dict())` when a collection starts."""
    actor = copy.deepcopy(model)
    for p in actor.parameters():
        p.requires_grad_(False)
    return actor


class Prefetch:
    """Runs `fn()` in a daemon thread from construction on.

    `result()` waits for it and returns its wall-clock seconds, or raises what `fn` raised
    (in the caller's thread, so a failed collection stops training with its own traceback).
    """

    def __init__(self, fn: Callable[[], None]) -> None:
        self._error: BaseException | None = None
        self._seconds = 0.0
        self._thread = threading.Thread(target=self._run, args=(fn,), name="spd-collect", daemon=True)
        self._thread.start()

    def _run(self, fn: Callable[[], None]) -> None:
        start = time.perf_counter()
        try:
            fn()
        except BaseException as exc:  # handed to the caller in result()
            self._error = exc
        self._seconds = time.perf_counter() - start

    def wait(self) -> None:
        """Block until `fn` returned or raised."""
        self._thread.join()

    def result(self) -> float:
        """Wait; the seconds `fn` took, or its exception re-raised."""
        self.wait()
        if self._error is not None:
            raise self._error
        return self._seconds
