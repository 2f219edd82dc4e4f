"""Type stub of the Cython module `selfplaydrive._sim.lanes` (only its Python-visible names).

Array arguments are typed memoryviews in Cython: C-contiguous NumPy arrays of the dtype the
docstrings of lanes.pyx name (float64 unless said otherwise); outputs are written in place.
"""

import numpy as np
from numpy.typing import NDArray

_F64 = NDArray[np.float64]
_I64 = NDArray[np.int64]
_F32 = NDArray[np.float32]
_I32 = NDArray[np.int32]
_Bool = NDArray[np.bool_]

def hash_uniforms(key: int, agents: int, draws: int) -> _F64: ...
def walk_routes(
    succ_off: _I64,
    succ_idx: _I64,
    left: _I64,
    right: _I64,
    length: _F64,
    speed: _F64,
    start_lane: _I64,
    start_s: _F64,
    horizon: _F64,
    key: int,
    p_change: float,
    min_change: float,
    changes: bool,
    lanes: _I64,
    s0: _F64,
    s1: _F64,
    change: _Bool,
    t_end: _F64,
    dead: _Bool,
) -> None: ...
def lane_points(
    gcum: _F64,
    px: _F64,
    py: _F64,
    heading: _F64,
    base: _F64,
    length: _F64,
    offsets: _I64,
    lane: _I64,
    s: _F64,
    out_xy: _F64,
    out_heading: _F64,
) -> None: ...
def route_waypoints_batch(
    lanes: _I64,
    s_start: _F64,
    s_end: _F64,
    t_end: _F64,
    times: _F64,
    speed: _F64,
    gcum: _F64,
    px: _F64,
    py: _F64,
    base: _F64,
    length: _F64,
    offsets: _I64,
    out_xy: _F32,
    out_count: _I32,
) -> None: ...
