"""Type stub of the Cython module `selfplaydrive._sim.placement` (only its Python-visible names).

Array arguments are typed memoryviews in Cython: C-contiguous NumPy arrays of the dtype the
docstrings of placement.pyx name (float64 unless said otherwise); outputs are written in place.
"""

from typing import Any

import numpy as np
from numpy.typing import NDArray

from selfplaydrive._sim.chunks import ChunkKernel

_F64 = NDArray[np.float64]
_I64 = NDArray[np.int64]
_F32 = NDArray[np.float32]
_Bool = NDArray[np.bool_]

def greedy_select(
    xy: _F64, radius: _F64, need: int, fixed_xy: _F64, fixed_radius: _F64, gap: float
) -> _I64: ...
def aligned_candidates(
    lane: _I64,
    s: _F64,
    xy: _F64,
    heading: _F64,
    sin_h: _F64,
    cos_h: _F64,
    length: _F64,
    width: _F64,
    u: _F64,
    lane_width: _F32,
    speed_limit: _F32,
    lateral_noise: float,
    heading_noise: float,
    speed_lo: float,
    speed_hi: float,
    out: _F64,
) -> None: ...
def roadside_poses(
    lane: _I64,
    chunk: _I64,
    xy: _F64,
    sin_h: _F64,
    cos_h: _F64,
    width: _F64,
    lane_width: _F32,
    edge: _F64,
    curb_gap: float,
    max_shoulder: float,
    min_free: float,
    out_xy: _F64,
    out_off: _F64,
    out_fits: _Bool,
) -> None: ...
def boxes_meet(
    ax: float,
    ay: float,
    ah: float,
    al: float,
    aw: float,
    bx: float,
    by: float,
    bh: float,
    bl: float,
    bw: float,
) -> bool: ...

class SizeTable:
    def __init__(self, sampler: Any) -> None: ...

class Placer:
    def __init__(
        self,
        sizes: Any,
        static_sizes: Any,
        min_agent_distance: float,
        first_round_candidates: int,
        candidates_per_agent: int,
        static_candidates_per_vehicle: int,
        lateral_noise: float,
        heading_noise: float,
        speed_lo: float,
        speed_hi: float,
        curb_gap: float,
        max_shoulder: float,
        static_gap: float,
        min_free_lane_width: float,
        clear_ahead: float,
        headway: float,
    ) -> None: ...
    def agents(
        self,
        spawn: ChunkKernel,
        roadside: ChunkKernel,
        rng: np.random.Generator,
        box: _F64,
        want: int,
        n_parked: int,
        sc: Any,
    ) -> tuple[int, int, _I64, _F64]: ...
    def statics(
        self,
        roadside: ChunkKernel,
        rng: np.random.Generator,
        box: _F64,
        want: int,
        n_agents: int,
        sc: Any,
    ) -> tuple[int, _F64, _F64, _Bool]: ...
