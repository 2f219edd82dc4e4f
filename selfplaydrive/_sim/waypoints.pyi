"""Type stub of the Cython module `selfplaydrive._sim.waypoints` (only its Python-visible names).

Array arguments are typed memoryviews in Cython: C-contiguous NumPy arrays of the dtype the
docstrings of waypoints.pyx name (float64 unless said otherwise); outputs are written in place.
"""

from typing import Any

import numpy as np
from numpy.typing import NDArray

_F64 = NDArray[np.float64]
_I64 = NDArray[np.int64]
_F32 = NDArray[np.float32]
_I32 = NDArray[np.int32]

class RouteKernel:
    @property
    def tables(self) -> Any: ...
    def __init__(self, tables: Any, lane_width: Any, speed_limit: Any) -> None: ...
    def waypoints(
        self,
        start_lane: _I64,
        start_s: _F64,
        times: _F64,
        key: int,
        p_change: float,
        min_change: float,
        max_pieces: int,
        out_xy: _F32,
        out_count: _I32,
    ) -> None: ...
    def draw_waypoints(
        self,
        rng: np.random.Generator,
        start_lane: _I64,
        start_s: _F64,
        max_waypoints: int,
        spacing: float,
        jitter: float,
        p_change: float,
        min_change: float,
        max_pieces: int,
        out_xy: _F32,
        out_count: _I32,
    ) -> None: ...
