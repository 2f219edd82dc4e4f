# cython: language_level=3
"""`RouteKernel` (_sim/waypoints.pyx): placement (_sim/placement.pyx) reads its lane tables."""

cimport numpy as cnp
from selfplaydrive._sim.spawn_common cimport f64, i64, u64


cdef class RouteKernel:
    cdef readonly object tables
    cdef const f64[::1] gcum, px, py, heading, base, length, speed, hsin, hcos
    cdef const cnp.float32_t[::1] lane_width, speed_limit
    cdef const i64[::1] offsets, succ_off, succ_idx, left, right
    cdef bint has_changes
    cdef object _lanes, _s0, _s1, _t_end, _change

    cdef int _waypoints(self, const i64[::1] start_lane, const f64[::1] start_s, const f64[:, ::1] times,
                        u64 key, double p_change, double min_change, Py_ssize_t max_pieces,
                        cnp.float32_t[:, :, ::1] out_xy, cnp.int32_t[::1] out_count) except -1
