# cython: language_level=3
"""Lane-graph kernels of one map (_sim/lanes.pyx): the parts the spawner's kernels call
(`RouteKernel` in waypoints.pyx, `ChunkKernel` in placement.pyx). Map-level: nothing here
depends on the spawner."""

cimport numpy as cnp

ctypedef cnp.float64_t f64
ctypedef cnp.int64_t i64
ctypedef cnp.uint64_t u64


cdef inline i64 _lane_piece(const f64[::1] gcum, const i64[::1] offsets, i64 ln, double g) noexcept nogil:
    """Centreline piece of lane `ln` holding flat arc length g: the largest lo with
    gcum[lo] <= g, within [offsets[ln], offsets[ln + 1] - 2] (binary search)."""
    cdef i64 lo = offsets[ln], hi = offsets[ln + 1] - 2, mid
    while lo < hi:
        mid = (lo + hi + 1) >> 1
        if gcum[mid] <= g:
            lo = mid
        else:
            hi = mid - 1
    return lo


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
