# cython: language_level=3
"""Lane-graph kernels of one map (_sim/lanes.pyx): the parts the spawner's `RouteKernel`
(_sim/waypoints.pyx) calls."""

cimport numpy as cnp
from selfplaydrive._sim.spawn_common cimport f64, i64, u64


cdef void walk_one(
    const i64[::1] succ_off, const i64[::1] succ_idx, const i64[::1] left, const i64[::1] right,
    const f64[::1] length, const f64[::1] speed, i64 lane, double s_in, double horizon,
    u64 key, u64 agent, double p_change, double min_change, bint changes,
    i64[::1] lanes, f64[::1] s0, f64[::1] s1, cnp.npy_bool[::1] change, f64[::1] t_end,
    cnp.npy_bool* dead,
) noexcept nogil

cdef void waypoints_into(
    const i64[:, ::1] lanes, const f64[:, ::1] s_start, const f64[:, ::1] s_end, const f64[:, ::1] t_end,
    const f64[:, ::1] times, const f64[::1] speed,
    const f64[::1] gcum, const f64[::1] px, const f64[::1] py, const f64[::1] base,
    const f64[::1] length, const i64[::1] offsets,
    cnp.float32_t[:, :, ::1] out_xy, cnp.int32_t[::1] out_count,
) noexcept nogil
