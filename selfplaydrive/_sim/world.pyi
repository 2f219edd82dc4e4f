"""Type stub of the Cython module `selfplaydrive._sim.world` (only its Python-visible names)."""

from typing import Any

import numpy as np
from numpy.typing import NDArray

STAGES: tuple[str, ...]

class World:
    timings: dict[str, float]
    def __init__(
        self,
        dims: dict[str, Any],
        state: dict[str, Any],
        layout: tuple[list[tuple[str, int, np.dtype[Any] | None]], int],
        atlas: dict[str, Any],
        params: dict[str, Any],
        terms: list[tuple[int, NDArray[np.float32] | None, float, int]],
        physics: tuple[int, NDArray[np.float32] | None],
        encoder: tuple[int, NDArray[Any] | None] | None = None,
    ) -> None: ...
    def physics_stage(self, num_threads: int = 1) -> None: ...
    def set_term_weight(self, k: int, weight: float) -> None: ...
    def step(self, num_threads: int = 1, profile: bool = False, chunk: int = 0) -> None: ...
    def encode(self, num_threads: int = 1) -> None: ...
    def after_reset(self, worlds: NDArray[Any], num_threads: int = 1) -> None: ...

def copy_discrete(
    a: NDArray[np.int32] | NDArray[np.int64], out: NDArray[np.int32], n_acc: int, n_steer: int
) -> int: ...
