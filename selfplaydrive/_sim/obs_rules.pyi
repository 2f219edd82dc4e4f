"""Type stub of the Cython module `selfplaydrive._sim.obs_rules` (only its Python-visible names)."""

from typing import Any

import numpy as np
from numpy.typing import NDArray

def head_size() -> int: ...
def encoder_address() -> int: ...
def occupied_flags(
    args: NDArray[Any],
    m: int,
    x: NDArray[np.float32],
    y: NDArray[np.float32],
    vx: NDArray[np.float32],
    vy: NDArray[np.float32],
) -> NDArray[np.bool_]: ...
