"""Type stub of the Cython module `selfplaydrive._sim.partial` (only its Python-visible names)."""

from typing import Any

import numpy as np
from numpy.typing import NDArray

ARGS_FIELDS: tuple[str, ...]

def args_size() -> int: ...
def encoder_address() -> int: ...
def stream_key(world_key: int, salt: int) -> int: ...
def scratch_doubles(max_obj: int) -> int: ...
def scratch_floats(max_obj: int) -> int: ...
def postprocess_rows(
    rows: NDArray[np.float32],
    n: int,
    args: NDArray[Any],
    key: int,
    step: int,
    slot: int,
    pos_scale: float,
    length_scale: float,
    width_scale: float,
    max_speed: float,
    radius: float,
) -> int: ...
