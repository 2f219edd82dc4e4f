"""Type stub of the Cython module `selfplaydrive._sim.chunks` (only its Python-visible names)."""

from typing import Any

import numpy as np
from numpy.typing import NDArray

from selfplaydrive._sim.waypoints import RouteKernel

_F64 = NDArray[np.float64]
_I64 = NDArray[np.int64]

class ChunkKernel:
    def __init__(self, chunks: Any, routes: RouteKernel) -> None: ...
    def poses(self, box: _F64, u: _F64) -> tuple[_I64, _F64, _F64, _F64, _I64]: ...
