# cython: language_level=3
"""Pose draws on lane chunks (paper section 2.2): `ChunkKernel` binds one `scenario.index.Chunks`
set (spawn or roadside chunks, in a grid of cells) and its map's route tables once; per
candidate, `gather` lists the chunks whose midpoint lies in the world's region and `pose` turns
two uniforms into a pose on them (`Placer`, _sim/placement.pyx). The NumPy twin of `poses` is
`testing.spawn_reference.sample_on_chunks_reference`.
"""

import numpy as np

cimport numpy as cnp
from libc.stdlib cimport free
from selfplaydrive._sim.lanes cimport _lane_piece
from selfplaydrive._sim.spawn_common cimport _alloc, _box_cells, _box_count

cnp.import_array()


cdef class ChunkKernel:
    """One `scenario.index.Chunks` set (and its map's route tables) bound once as typed views:
    `gather` lists the chunks whose midpoint lies in a box with their cumulative lengths, `pose`
    turns two uniforms into a pose on them; `poses` runs both for n draws (its NumPy twin is
    `testing.spawn_reference.sample_on_chunks_reference`)."""

    def __init__(self, chunks, RouteKernel routes):
        cells = chunks.cells
        self.cell_origin = np.ascontiguousarray(cells.origin, dtype=np.float64)
        self.cell = float(cells.cell)
        self.nx = int(cells.shape[0])
        self.ny = int(cells.shape[1])
        self.cell_offsets = cells.offsets
        self.cell_items = cells.items
        self.mid = cells.xy
        self.chunk_lane = chunks.lane
        self.chunk_s0 = chunks.s0
        self.chunk_s1 = chunks.s1
        self.edge = np.ascontiguousarray(chunks.edge, dtype=np.float64)
        # midpoints and lengths in cell order, so `gather` reads them contiguously
        self.sorted_mid = np.ascontiguousarray(np.asarray(cells.xy)[cells.items], dtype=np.float64)
        self.sorted_len = np.ascontiguousarray((chunks.s1 - chunks.s0)[cells.items], dtype=np.float64)
        self.r = routes

    cdef Py_ssize_t count(self, const f64[::1] box) noexcept:
        """Room `gather` needs for `box` (the chunks in the cells that meet it)."""
        return _box_count(self.cell_origin, self.cell, self.nx, self.ny, self.cell_offsets, box)

    cdef Py_ssize_t gather(self, const f64[::1] box, i64* ids, f64* cdf) noexcept:
        """The chunks whose midpoint lies in `box` (`CellIndex.query_box`, cell order) into ids
        and their cumulative lengths [m] into cdf (room for `count(box)` entries each); returns
        their number."""
        cdef Py_ssize_t r[4]
        cdef Py_ssize_t i, c, n = 0
        cdef double total = 0.0
        if not _box_cells(self.cell_origin, self.cell, self.nx, self.ny, box, r):
            return 0
        for i in range(r[0], r[2] + 1):
            for c in range(self.cell_offsets[i * self.ny + r[1]], self.cell_offsets[i * self.ny + r[3] + 1]):
                if box[0] <= self.sorted_mid[c, 0] <= box[2] and box[1] <= self.sorted_mid[c, 1] <= box[3]:
                    ids[n] = self.cell_items[c]
                    total += self.sorted_len[c]
                    cdf[n] = total
                    n += 1
        return n

    cdef bint pose(self, const i64* ids, const f64* cdf, Py_ssize_t n, const f64[::1] box,
                   double u0, double u1, Pose* p) noexcept:
        """The pose of draw (u0, u1) on the n > 0 gathered chunks: u0 picks a chunk with
        probability proportional to its length (the first whose cumulative length exceeds
        u0 * total), u1 the arc length inside it; False when the point lies outside `box`."""
        cdef RouteKernel r = self.r
        cdef i64 lo = 0, hi = n - 1, md, ch, ln
        cdef double target = u0 * cdf[n - 1], g, f
        while lo < hi:
            md = (lo + hi) >> 1
            if cdf[md] > target:
                hi = md
            else:
                lo = md + 1
        ch = ids[lo]
        ln = self.chunk_lane[ch]
        p.chunk = ch
        p.lane = ln
        p.s = self.chunk_s0[ch] + u1 * (self.chunk_s1[ch] - self.chunk_s0[ch])
        g = r.base[ln] + p.s
        lo = _lane_piece(r.gcum, r.offsets, ln, g)
        p.piece = lo
        f = (g - r.gcum[lo]) / (r.gcum[lo + 1] - r.gcum[lo])
        p.x = r.px[lo] + f * (r.px[lo + 1] - r.px[lo])
        p.y = r.py[lo] + f * (r.py[lo + 1] - r.py[lo])
        return box[0] <= p.x <= box[2] and box[1] <= p.y <= box[3]

    def poses(self, const f64[::1] box, const f64[:, ::1] u):
        """(lane, s, xy, heading, chunk) of the poses drawn with u (n, 2) (`pose` of each row)
        that lie in `box`."""
        cdef Py_ssize_t n = u.shape[0], m = 0, q, n_ids, k = self.count(box)
        cdef Pose p
        lane_arr = np.empty(n, dtype=np.int64)
        s_arr = np.empty(n)
        xy_arr = np.empty((n, 2))
        h_arr = np.empty(n)
        chunk_arr = np.empty(n, dtype=np.int64)
        cdef i64[::1] lane = lane_arr, chunk = chunk_arr
        cdef f64[::1] s = s_arr, h = h_arr
        cdef f64[:, ::1] xy = xy_arr
        cdef i64* ids
        cdef f64* cdf
        if n > 0 and k > 0:
            ids = <i64*>_alloc(k * sizeof(i64))
            cdf = <f64*>_alloc(k * sizeof(f64))
            try:
                n_ids = self.gather(box, ids, cdf)
                for q in range(n if n_ids > 0 else 0):
                    if self.pose(ids, cdf, n_ids, box, u[q, 0], u[q, 1], &p):
                        lane[m] = p.lane
                        s[m] = p.s
                        xy[m, 0] = p.x
                        xy[m, 1] = p.y
                        h[m] = self.r.heading[p.piece]
                        chunk[m] = p.chunk
                        m += 1
            finally:
                free(ids)
                free(cdf)
        return lane_arr[:m], s_arr[:m], xy_arr[:m], h_arr[:m], chunk_arr[:m]
