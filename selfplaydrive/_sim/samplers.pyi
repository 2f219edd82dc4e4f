"""Type stub of the Cython module `selfplaydrive._sim.samplers` (only its Python-visible names).

Array arguments are typed memoryviews in Cython: C-contiguous NumPy arrays of the dtype the
docstrings of samplers.pyx name (float64 unless said otherwise); outputs are written in place.
"""

import numpy as np
from numpy.typing import NDArray

_F64 = NDArray[np.float64]
_I64 = NDArray[np.int64]
_F32 = NDArray[np.float32]

def vehicle_sizes(
    u: _F64, cdf: _F64, length_tab: _F64, width_tab: _F64, jitter: float, max_width: float
) -> tuple[_F64, _F64, _I64]: ...
def bimodal_uniform(
    u: _F64,
    lo: _F64,
    hi: _F64,
    c: int,
    c_lo: float,
    c_hi: float,
    p_c: float,
    a: int,
    a_lo: float,
    a_hi: float,
    p_a: float,
) -> _F32: ...
