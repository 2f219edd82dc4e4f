# cython: language_level=3
"""Radius queries over the uniform segment grid of a RoadMap (see maps/compile.py:build_grid).

The simulator's observation and event kernels call `grid_query` per agent without the GIL;
`query_radius_batch` is the Python entry used by tools, tests and the map benchmark.
"""

import numpy as np

cimport numpy as cnp
from libc.math cimport floor

cnp.import_array()


cdef int grid_query(const float[:, ::1] mid, const int[::1] cell_offsets, const int[::1] cell_items,
                    float ox, float oy, float cell, int nx, int ny,
                    float x, float y, float radius, int* out, int cap) noexcept nogil:
    """Write up to `cap` segment indices with midpoint within `radius` of (x, y) to `out`.

    Returns the number found (possibly more than `cap`: only the first `cap` are written).
    Order is grid order (x-major cells), deterministic.
    """
    cdef int lo_x = <int>floor((x - radius - ox) / cell)
    cdef int hi_x = <int>floor((x + radius - ox) / cell)
    cdef int lo_y = <int>floor((y - radius - oy) / cell)
    cdef int hi_y = <int>floor((y + radius - oy) / cell)
    cdef int ix, k, s, n = 0, c0
    cdef float dx, dy, r2 = radius * radius
    if lo_x < 0:
        lo_x = 0
    if lo_y < 0:
        lo_y = 0
    if hi_x > nx - 1:
        hi_x = nx - 1
    if hi_y > ny - 1:
        hi_y = ny - 1
    if lo_y > hi_y:
        return 0
    for ix in range(lo_x, hi_x + 1):
        c0 = ix * ny
        for k in range(cell_offsets[c0 + lo_y], cell_offsets[c0 + hi_y + 1]):
            s = cell_items[k]
            dx = mid[s, 0] - x
            dy = mid[s, 1] - y
            if dx * dx + dy * dy <= r2:
                if n < cap:
                    out[n] = s
                n += 1
    return n


def query_radius_batch(road_map, points, float radius, int cap=4096):
    """Count and collect segments within `radius` [m] of each query point.

    Args:
        road_map: A compiled `RoadMap`.
        points: (Q, 2) float32 query positions [m], local frame.
        radius: [m].
        cap: Max indices kept per query.

    Returns:
        (counts, indices): (Q,) int32 number found; (Q, cap) int32 indices, -1 padded.
    """
    cdef const float[:, ::1] mid = np.ascontiguousarray(road_map.segments.mid, dtype=np.float32)
    cdef const int[::1] offs = np.ascontiguousarray(road_map.grid.cell_offsets, dtype=np.int32)
    cdef const int[::1] items = np.ascontiguousarray(road_map.grid.cell_items, dtype=np.int32)
    cdef const float[:, ::1] q = np.ascontiguousarray(points, dtype=np.float32)
    cdef int nq = q.shape[0]
    counts_np = np.zeros(nq, dtype=np.int32)
    out_np = np.full((nq, cap), -1, dtype=np.int32)
    cdef int[::1] counts = counts_np
    cdef int[:, ::1] out = out_np
    cdef float ox = road_map.grid.origin[0], oy = road_map.grid.origin[1]
    cdef float cell = road_map.grid.cell_size
    cdef int nx = road_map.grid.shape[0], ny = road_map.grid.shape[1]
    cdef int i
    with nogil:
        for i in range(nq):
            counts[i] = grid_query(mid, offs, items, ox, oy, cell, nx, ny, q[i, 0], q[i, 1], radius, &out[i, 0], cap)
    return counts_np, out_np
