"""Type stub of the Cython module `selfplaydrive._sim.pedestrians` (only its Python-visible names).

Array arguments are typed memoryviews in Cython: C-contiguous NumPy arrays of the dtype the
docstrings of pedestrians.pyx name (float64 unless said otherwise); outputs are written in place.
"""

from typing import Any

import numpy as np
from numpy.typing import NDArray

_F64 = NDArray[np.float64]
_I64 = NDArray[np.int64]
_Bool = NDArray[np.bool_]

class CrossingKernel:
    def __init__(self, crossings: Any) -> None: ...
    def query_box(self, box: _F64) -> _I64: ...

def pedestrian_sites(
    crosswalks: CrossingKernel, crossings: CrossingKernel, box: _F64
) -> tuple[int, int, _I64, _I64]: ...
def pedestrian_paths(
    crosswalks: CrossingKernel,
    crossings: CrossingKernel,
    cw: _I64,
    other: _I64,
    u: _F64,
    share: float,
    margin: float,
    max_approach: float,
    veh_xy: _F64,
    clear_r: _F64,
    still: _Bool,
    path: _F64,
    ok: _Bool,
) -> None: ...
def pedestrian_batch(
    sampler: Any,
    crosswalks: CrossingKernel,
    crossings: CrossingKernel,
    rng: np.random.Generator,
    box: _F64,
    want: int,
    veh_xy: _F64,
    veh_r: _F64,
    still: _Bool,
    out: Any,
) -> int: ...
