# cython: language_level=3
"""`ChunkKernel` (_sim/chunks.pyx): pose draws on a set of lane chunks, which `Placer`
(_sim/placement.pyx) calls once per candidate."""

from selfplaydrive._sim.spawn_common cimport f64, i64
from selfplaydrive._sim.waypoints cimport RouteKernel


cdef struct Pose:
    # a pose drawn on a chunk: chunk, lane, centreline piece (index of its heading), arc length
    # on the lane [m], point on the centreline [m]
    i64 chunk
    i64 lane
    i64 piece
    double s
    double x
    double y


cdef class ChunkKernel:
    cdef const f64[::1] cell_origin, chunk_s0, chunk_s1, edge, sorted_len
    cdef double cell
    cdef Py_ssize_t nx, ny
    cdef const i64[::1] cell_offsets, cell_items, chunk_lane
    cdef const f64[:, ::1] mid, sorted_mid
    cdef RouteKernel r

    cdef Py_ssize_t count(self, const f64[::1] box) noexcept
    cdef Py_ssize_t gather(self, const f64[::1] box, i64* ids, f64* cdf) noexcept
    cdef bint pose(self, const i64* ids, const f64* cdf, Py_ssize_t n, const f64[::1] box,
                   double u0, double u1, Pose* p) noexcept
