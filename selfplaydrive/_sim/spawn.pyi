"""Type stub of the Cython module `selfplaydrive._sim.spawn` (only its Python-visible names).

Array arguments are typed memoryviews in Cython: C-contiguous NumPy arrays of the dtype the
docstrings of spawn.pyx name (float64 unless said otherwise); outputs are written in place.
"""

from typing import Any

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
def greedy_select(
    xy: _F64, radius: _F64, need: int, fixed_xy: _F64, fixed_radius: _F64, gap: float
) -> _I64: ...
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

class ChunkKernel:
    def __init__(self, chunks: Any, routes: RouteKernel) -> None: ...
    def poses(self, box: _F64, u: _F64) -> tuple[_I64, _F64, _F64, _F64, _I64]: ...

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
def vehicle_sizes(
    u: _F64, cdf: _F64, length_tab: _F64, width_tab: _F64, jitter: float, max_width: float
) -> tuple[_F64, _F64, _I64]: ...
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
