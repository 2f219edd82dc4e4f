# cython: language_level=3
"""Pedestrian kernels (paper section 2.2): crossing sites in a world's region (`CrossingKernel`)
and pedestrians with paths across them, clear of the vehicles (`pedestrian_batch`, the body
of `scenario.pedestrians.PedestrianSampler.sample`). Draws come from the world's generator;
the NumPy references are in `selfplaydrive/testing/spawn_reference.py`.
"""

import numpy as np

cimport numpy as cnp
from libc.math cimport hypot
from libc.stdlib cimport free
from numpy.random cimport bitgen_t
from selfplaydrive._sim.spawn_common cimport (
    f64, i64, _alloc, _bitgen, _box_cells, _box_count, _draw, _field,
)

cnp.import_array()


cdef class CrossingKernel:
    """One `scenario.index.Crossings` set bound once as typed views (pedestrian sites)."""

    cdef const f64[::1] cell_origin, half
    cdef double cell
    cdef Py_ssize_t nx, ny
    cdef const i64[::1] cell_offsets, cell_items
    cdef const f64[:, ::1] mid, start, end

    def __init__(self, crossings):
        cells = crossings.cells
        self.cell_origin = np.ascontiguousarray(cells.origin, dtype=np.float64)
        self.cell = float(cells.cell)
        self.nx = int(cells.shape[0])
        self.ny = int(cells.shape[1])
        self.cell_offsets = cells.offsets
        self.cell_items = cells.items
        self.mid = np.ascontiguousarray(cells.xy, dtype=np.float64)
        self.start = np.ascontiguousarray(crossings.start, dtype=np.float64)
        self.end = np.ascontiguousarray(crossings.end, dtype=np.float64)
        self.half = np.ascontiguousarray(crossings.half_width, dtype=np.float64)

    cdef Py_ssize_t count(self, const f64[::1] box) noexcept:
        """Room `query` needs for `box`."""
        return _box_count(self.cell_origin, self.cell, self.nx, self.ny, self.cell_offsets, box)

    cdef Py_ssize_t query(self, const f64[::1] box, i64* out) noexcept:
        """`CellIndex.query_box`: the sites whose midpoint lies in box, in cell order, into out
        (room for `count(box)` entries); returns their number."""
        cdef Py_ssize_t r[4]
        cdef Py_ssize_t i, c, m = 0
        cdef i64 p
        if not _box_cells(self.cell_origin, self.cell, self.nx, self.ny, box, r):
            return 0
        for i in range(r[0], r[2] + 1):
            for c in range(self.cell_offsets[i * self.ny + r[1]], self.cell_offsets[i * self.ny + r[3] + 1]):
                p = self.cell_items[c]
                if (self.mid[p, 0] >= box[0] and self.mid[p, 0] <= box[2] and self.mid[p, 1] >= box[1]
                        and self.mid[p, 1] <= box[3]):
                    out[m] = p
                    m += 1
        return m

    def query_box(self, const f64[::1] box):
        """(k,) int64 `CellIndex.query_box(box)` of the crossings' midpoints."""
        out = np.empty(self.count(box), dtype=np.int64)
        return out[:self.query(box, <i64*>cnp.PyArray_DATA(out))]


def pedestrian_sites(CrossingKernel crosswalks, CrossingKernel crossings, const f64[::1] box):
    """Numbers of crosswalk and other crossing sites in `box` and both index arrays:
    (n_cw, n_other, cw, other)."""
    cw = crosswalks.query_box(box)
    other = crossings.query_box(box)
    return len(cw), len(other), cw, other


cdef bint _ped_path(
    CrossingKernel crosswalks, CrossingKernel crossings, const i64* cw, Py_ssize_t n_cw,
    const i64* other, Py_ssize_t n_other, const f64* u, double share, double margin,
    double max_approach, const f64* veh_xy, const f64* veh_r, double clearance,
    const cnp.npy_bool* still, Py_ssize_t nv, f64* path,
) noexcept:
    """One pedestrian of `scenario.pedestrians.PedestrianSampler.sample` from its draws u[0:6]:
    site choice, the path (approach point, crossing start, crossing end) into path[0:6], and
    whether its first point keeps veh_r + clearance from every vehicle centre and no leg of it
    passes that close to a vehicle with `still` set (still may be NULL: none)."""
    cdef Py_ssize_t v, k
    cdef bint use_cw
    cdef i64 site, pick, lim
    cdef double sx, sy, ex, ey, hw, dx, dy, norm, sdx, sdy, sh, ax, ay, bx, by, sign, tmp
    cdef double wx, wy, t, gx, gy, dd, r
    cdef CrossingKernel kk
    use_cw = (u[0] < share) if n_cw else False
    if use_cw:
        site = <i64>(u[1] * n_cw)
        lim = n_cw
    else:
        site = <i64>(n_cw + u[1] * n_other)
        lim = n_cw + n_other
    pick = site if site < lim - 1 else lim - 1
    if pick < n_cw:
        kk = crosswalks
        k = cw[pick]
    else:
        kk = crossings
        k = other[pick - n_cw]
    sx = kk.start[k, 0]
    sy = kk.start[k, 1]
    ex = kk.end[k, 0]
    ey = kk.end[k, 1]
    hw = kk.half[k]
    dx = ex - sx
    dy = ey - sy
    norm = hypot(dx, dy)
    if norm < 1e-9:  # np.maximum(norm, 1e-9) (NaN stays NaN)
        norm = 1e-9
    dx = dx / norm
    dy = dy / norm
    sdx = -dy
    sdy = dx
    sh = hw * (2.0 * u[2] - 1.0)
    if u[3] < 0.5:
        ax = ex + sh * sdx
        ay = ey + sh * sdy
        bx = sx + sh * sdx
        by = sy + sh * sdy
        dx = -dx
        dy = -dy
    else:
        ax = sx + sh * sdx
        ay = sy + sh * sdy
        bx = ex + sh * sdx
        by = ey + sh * sdy
    ax = ax - dx * margin
    ay = ay - dy * margin
    bx = bx + dx * margin
    by = by + dy * margin
    sign = -1.0 if u[4] < 0.5 else 1.0
    tmp = sign * max_approach * u[5]
    path[0] = ax + sdx * tmp
    path[1] = ay + sdy * tmp
    path[2] = ax
    path[3] = ay
    path[4] = bx
    path[5] = by
    # the first point clear of every vehicle, every leg clear of the standing ones
    for v in range(nv):
        r = veh_r[v] + clearance
        dx = path[0] - veh_xy[2 * v]
        dy = path[1] - veh_xy[2 * v + 1]
        if not dx * dx + dy * dy >= r * r:
            return False
    for v in range(nv if still != NULL else 0):
        if not still[v]:
            continue
        r = veh_r[v] + clearance
        r = r * r
        for k in range(2):
            dx = path[2 * k + 2] - path[2 * k]
            dy = path[2 * k + 3] - path[2 * k + 1]
            wx = veh_xy[2 * v] - path[2 * k]
            wy = veh_xy[2 * v + 1] - path[2 * k + 1]
            dd = dx * dx + dy * dy
            if dd < 1e-12:
                dd = 1e-12
            t = (wx * dx + wy * dy) / dd
            t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
            gx = wx - t * dx
            gy = wy - t * dy
            if not gx * gx + gy * gy >= r:
                return False
    return True


def pedestrian_paths(
    CrossingKernel crosswalks, CrossingKernel crossings, const i64[::1] cw, const i64[::1] other,
    const f64[:, ::1] u, double share, double margin, double max_approach,
    const f64[:, ::1] veh_xy, const f64[::1] clear_r, const cnp.npy_bool[::1] still,
    f64[:, :, ::1] path, cnp.npy_bool[::1] ok,
):
    """`_ped_path` of each row of the draws u (n, 9) (columns 0-5 used): (n, 3, 2) paths into
    `path` and ok[i] when path i keeps clear_r from the vehicles (clearance included)."""
    cdef Py_ssize_t i, n = u.shape[0]
    cdef i64 dummy = 0
    for i in range(n):
        ok[i] = _ped_path(crosswalks, crossings, &cw[0] if cw.shape[0] else &dummy, cw.shape[0],
                          &other[0] if other.shape[0] else &dummy, other.shape[0], &u[i, 0], share,
                          margin, max_approach, &veh_xy[0, 0] if veh_xy.shape[0] else NULL, &clear_r[0] if clear_r.shape[0] else NULL, 0.0,
                          &still[0] if still.shape[0] else NULL, veh_xy.shape[0], &path[i, 0, 0])


def pedestrian_batch(
    object sampler, CrossingKernel crosswalks, CrossingKernel crossings, object rng,
    const f64[::1] box, Py_ssize_t want, const f64[:, ::1] veh_xy, const f64[::1] veh_r,
    const cnp.npy_bool[::1] still, object out,
):
    """The body of `scenario.pedestrians.PedestrianSampler.sample` (`sampler`'s settings) after
    its count draw: the sites in `box`; when there are any, the (want, 9) draws (pool, site,
    sideways shift, direction, kerb side, approach, speed, start time, size; the next values of
    `rng.random`), `_ped_path` of each pedestrian and the kept ones written in order into the
    `PedestrianBatch` `out`. Returns their number."""
    cdef Py_ssize_t k_cw = crosswalks.count(box), k_o = crossings.count(box), n_cw, n_other, i, k, n = 0
    cdef Py_ssize_t nv = veh_xy.shape[0], slots
    cdef double share = sampler.crosswalk_share, margin = sampler.sidewalk_margin
    cdef double approach = sampler.max_approach, clearance = sampler.vehicle_clearance
    cdef double sp_lo = sampler.speed[0], sp_hi = sampler.speed[1]
    cdef double st_lo = sampler.start_time[0], st_hi = sampler.start_time[1]
    cdef double sz_lo = sampler.size[0], sz_hi = sampler.size[1], size
    cdef double p[6]
    cdef bitgen_t* bg = _bitgen(rng)
    if veh_r.shape[0] != nv or still.shape[0] != nv:
        raise ValueError(f"pedestrian_batch: {nv} vehicle centres but {veh_r.shape[0]} radii and "
                         f"{still.shape[0]} stationary flags")
    slots = len(out.valid)
    if want > slots:
        raise ValueError(f"pedestrian_batch: want={want} pedestrians but only {slots} slots")
    cdef cnp.npy_bool* valid = <cnp.npy_bool*>_field(out, "valid", cnp.NPY_BOOL, slots)
    cdef float* path = <float*>_field(out, "path", cnp.NPY_FLOAT32, slots * 6)
    cdef cnp.int32_t* num_points = <cnp.int32_t*>_field(out, "num_points", cnp.NPY_INT32, slots)
    cdef float* speed = <float*>_field(out, "speed", cnp.NPY_FLOAT32, slots)
    cdef float* start_time = <float*>_field(out, "start_time", cnp.NPY_FLOAT32, slots)
    cdef float* size_out = <float*>_field(out, "size", cnp.NPY_FLOAT32, 2 * slots)
    if (<cnp.ndarray>out.path).shape[1] != 3:
        raise ValueError(f"pedestrian_batch: paths of 3 points expected, got {out.path.shape}")
    cdef i64* cw = <i64*>_alloc(k_cw * sizeof(i64))
    cdef i64* other = NULL
    cdef f64* u = NULL
    try:
        other = <i64*>_alloc(k_o * sizeof(i64))
        u = <f64*>_alloc(want * 9 * sizeof(f64))
        n_cw = crosswalks.query(box, cw)
        n_other = crossings.query(box, other)
        if n_cw + n_other == 0:
            return 0
        if n_other == 0:
            share = 1.0
        with rng.bit_generator.lock:
            _draw(bg, u, want * 9)
        for i in range(want):
            if not _ped_path(crosswalks, crossings, cw, n_cw, other, n_other, u + 9 * i, share, margin,
                             approach, &veh_xy[0, 0] if nv else NULL, &veh_r[0] if nv else NULL,
                             clearance, &still[0] if nv else NULL, nv, p):
                continue
            valid[n] = True
            for k in range(6):
                path[6 * n + k] = <float>p[k]
            num_points[n] = 3
            speed[n] = <float>(sp_lo + (sp_hi - sp_lo) * u[9 * i + 6])
            start_time[n] = <float>(st_lo + (st_hi - st_lo) * u[9 * i + 7])
            size = sz_lo + (sz_hi - sz_lo) * u[9 * i + 8]
            size_out[2 * n] = <float>size
            size_out[2 * n + 1] = <float>size
            n += 1
    finally:
        free(cw)
        free(other)
        free(u)
    return n
