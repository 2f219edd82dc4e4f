# cython: language_level=3
"""Spawner kernels (paper section 2.2): random route walks and greedy spaced selection.

They run once per world reset from `selfplaydrive.scenario` and `selfplaydrive.maps.routing`;
NumPy references with the same semantics are in `selfplaydrive/testing/spawn_reference.py`
and the tests compare them.
"""

import numpy as np

cimport numpy as cnp
from libc.math cimport hypot, fmod

cnp.import_array()

ctypedef cnp.float64_t f64
ctypedef cnp.int64_t i64
ctypedef cnp.uint64_t u64


cdef inline double hash_uniform(u64 key, u64 agent, u64 i) noexcept nogil:
    """Counter-based uniform in [0, 1): splitmix64 of (key, agent, draw index). Draw i of agent
    a is the same whatever else is drawn, so a route walk needs no pre-drawn array;
    `testing.spawn_reference.hash_uniforms` is the NumPy twin."""
    cdef u64 z = key ^ (agent << 40) ^ i
    z = z + <u64>0x9E3779B97F4A7C15
    z = (z ^ (z >> 30)) * <u64>0xBF58476D1CE4E5B9
    z = (z ^ (z >> 27)) * <u64>0x94D049BB133111EB
    z = z ^ (z >> 31)
    return <double>(z >> 11) * (1.0 / 9007199254740992.0)


cdef inline i64 _change_target(const i64[::1] left, const i64[::1] right, i64 lane, double u) noexcept nogil:
    """Legal lane-change target of `lane` (left or right by u when both exist) or -1."""
    cdef i64 l = left[lane]
    cdef i64 r = right[lane]
    if l >= 0 and r >= 0:
        return l if u < 0.5 else r
    return l if l > r else r


cdef void _walk_one(
    const i64[::1] succ_off, const i64[::1] succ_idx, const i64[::1] left, const i64[::1] right,
    const f64[::1] length, const f64[::1] speed, i64 lane, double s_in, double horizon,
    u64 key, u64 agent, double p_change, double min_change, bint changes,
    i64[::1] lanes, f64[::1] s0, f64[::1] s1, cnp.npy_bool[::1] change, f64[::1] t_end,
    cnp.npy_bool* dead,
) noexcept nogil:
    """Walk one route; see `maps.routing.sample_routes` for the rules."""
    cdef Py_ssize_t step, j, n = lanes.shape[0]
    cdef double t = 0.0, L, end, s_next
    cdef i64 target, nxt, deg, k
    cdef bint lc, prev = False
    for step in range(n):
        L = length[lane]
        end = L
        lc = False
        target = -1
        if changes:
            target = _change_target(left, right, lane, hash_uniform(key, agent, 3 * step + 1))
            lc = (hash_uniform(key, agent, 3 * step) < p_change and target >= 0 and not prev
                  and L - s_in >= min_change)
            if lc:
                end = 0.5 * (L + s_in)
        lanes[step] = lane
        s0[step] = s_in
        s1[step] = end
        change[step] = lc
        t = t + (end - s_in) / speed[lane]
        t_end[step] = t
        deg = succ_off[lane + 1] - succ_off[lane]
        nxt = -1
        if deg > 0:
            k = <i64>(hash_uniform(key, agent, 3 * step + 2) * deg)
            if k > deg - 1:
                k = deg - 1
            nxt = succ_idx[succ_off[lane] + k]
        s_next = 0.0
        if lc:
            nxt = target
            s_next = end * length[nxt] / L
        if nxt < 0:
            dead[0] = True
        if nxt < 0 or t >= horizon:
            for j in range(step + 1, n):
                t_end[j] = t
            return
        lane = nxt
        s_in = s_next
        prev = lc


def hash_uniforms(u64 key, Py_ssize_t agents, Py_ssize_t draws):
    """(agents, draws) float64 array of `hash_uniform(key, a, i)` (tests compare the NumPy twin)."""
    out = np.empty((agents, draws), dtype=np.float64)
    cdef f64[:, ::1] o = out
    cdef Py_ssize_t a, i
    for a in range(agents):
        for i in range(draws):
            o[a, i] = hash_uniform(key, a, i)
    return out


def walk_routes(
    const i64[::1] succ_off, const i64[::1] succ_idx, const i64[::1] left, const i64[::1] right,
    const f64[::1] length, const f64[::1] speed, const i64[::1] start_lane, const f64[::1] start_s,
    const f64[::1] horizon, u64 key, double p_change, double min_change, bint changes,
    i64[:, ::1] lanes, f64[:, ::1] s0, f64[:, ::1] s1, cnp.npy_bool[:, ::1] change, f64[:, ::1] t_end,
    cnp.npy_bool[::1] dead,
):
    """Random legal routes of A agents into preallocated (A, n) outputs.

    Args:
        succ_off, succ_idx: Successor CSR (int64).
        left, right: (L,) legal lane-change targets or -1.
        length, speed: (L,) lane length [m] and speed limit [m/s].
        start_lane, start_s, horizon: (A,) start lane, start arc length [m], wanted duration [s].
        key: Random key; step k of agent a uses `hash_uniform(key, a, 3k + j)` for j = 0
            (change?), 1 (which side), 2 (which successor).
        p_change: Lane-change probability per step; min_change: lane left needed [m].
        changes: Whether lane changes are considered at all.
        lanes, s0, s1, change, t_end: (A, n) outputs; `lanes` must be prefilled with -1 and
            s0/s1/t_end with 0.
        dead: (A,) output, route ended at a dead end (prefilled False).
    """
    cdef Py_ssize_t a, n_agents = start_lane.shape[0]
    cdef double s
    with nogil:
        for a in range(n_agents):
            s = start_s[a]
            if s < 0.0:
                s = 0.0
            if s > length[start_lane[a]]:
                s = length[start_lane[a]]
            _walk_one(succ_off, succ_idx, left, right, length, speed, start_lane[a], s, horizon[a],
                      key, a, p_change, min_change, changes, lanes[a], s0[a], s1[a], change[a], t_end[a],
                      &dead[a])


def greedy_select(
    const f64[:, ::1] xy, const f64[::1] radius, Py_ssize_t need,
    const f64[:, ::1] fixed_xy, const f64[::1] fixed_radius, double gap,
):
    """Indices of candidates accepted greedily in order while keeping
    |xy_i - xy_j| >= r_i + r_j + gap to every accepted candidate and fixed object.

    Returns:
        (m,) int64 accepted indices, m <= need.
    """
    cdef Py_ssize_t n = xy.shape[0], nf = fixed_xy.shape[0], i, j, m = 0
    out = np.empty(min(n, need) if need > 0 else 0, dtype=np.int64)
    cdef i64[::1] acc = out
    cdef double dx, dy, lim
    cdef bint ok
    if need <= 0:
        return out
    with nogil:
        for i in range(n):
            ok = True
            for j in range(nf):
                dx = xy[i, 0] - fixed_xy[j, 0]
                dy = xy[i, 1] - fixed_xy[j, 1]
                lim = radius[i] + fixed_radius[j] + gap
                if dx * dx + dy * dy < lim * lim:
                    ok = False
                    break
            if ok:
                for j in range(m):
                    dx = xy[i, 0] - xy[acc[j], 0]
                    dy = xy[i, 1] - xy[acc[j], 1]
                    lim = radius[i] + radius[acc[j]] + gap
                    if dx * dx + dy * dy < lim * lim:
                        ok = False
                        break
            if ok:
                acc[m] = i
                m += 1
                if m >= need:
                    break
    return out[:m]


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


def lane_points(
    const f64[::1] gcum, const f64[::1] px, const f64[::1] py, const f64[::1] heading,
    const f64[::1] base, const f64[::1] length, const i64[::1] offsets,
    const i64[::1] lane, const f64[::1] s, f64[:, ::1] out_xy, f64[::1] out_heading,
):
    """Points at arc length s [m] on lanes (binary search inside each lane's centreline).

    Args:
        gcum, px, py, heading: (P,) flat arc-length axis, coordinates [m] and piece headings [rad]
            (`maps.routing.RouteTables`).
        base, length: (L,) start of each lane on the axis and its length [m].
        offsets: (L + 1,) centreline CSR offsets.
        lane, s: (n,) queries; s is clamped to [0, length].
        out_xy: (n, 2) output [m]; out_heading: (n,) output [rad].
    """
    cdef Py_ssize_t q, n = lane.shape[0]
    cdef i64 lo, ln
    cdef double g, ss, f
    with nogil:
        for q in range(n):
            ln = lane[q]
            ss = s[q]
            if ss < 0.0:
                ss = 0.0
            if ss > length[ln]:
                ss = length[ln]
            g = base[ln] + ss
            lo = _lane_piece(gcum, offsets, ln, g)
            f = (g - gcum[lo]) / (gcum[lo + 1] - gcum[lo])
            out_xy[q, 0] = px[lo] + f * (px[lo + 1] - px[lo])
            out_xy[q, 1] = py[lo] + f * (py[lo + 1] - py[lo])
            out_heading[q] = heading[lo]


def sample_chunk_poses(
    const f64[::1] cell_origin, double cell, Py_ssize_t nx, Py_ssize_t ny,
    const i64[::1] cell_offsets, const i64[::1] cell_items, const f64[:, ::1] mid,
    const i64[::1] chunk_lane, const f64[::1] chunk_s0, const f64[::1] chunk_s1,
    const f64[::1] box, const f64[:, ::1] u,
    const f64[::1] gcum, const f64[::1] px, const f64[::1] py, const f64[::1] heading,
    const f64[::1] base, const f64[::1] length, const i64[::1] offsets,
    i64[::1] out_chunk, f64[::1] out_s, f64[:, ::1] out_xy, f64[::1] out_heading,
):
    """Poses uniform over the length of the chunks whose midpoint lies in `box`.

    Fuses `CellIndex.query_box`, the length-weighted chunk choice and `RouteTables.points`
    (the NumPy path is `testing.spawn_reference.sample_on_chunks_reference`). Draw q uses u[q, 0] to
    pick the chunk and u[q, 1] for the position inside it; poses outside `box` are dropped.
    `ChunkKernel.poses` runs the same code on tables bound once per map.

    Returns:
        Number m of poses written to the first m rows of the outputs.
    """
    cdef Py_ssize_t k = _box_count(cell_origin, cell, nx, ny, cell_offsets, box)
    if u.shape[0] == 0 or k == 0:
        return 0
    ids_arr = np.empty(k, dtype=np.int64)
    cdf_arr = np.empty(k, dtype=np.float64)
    return _chunk_poses(cell_origin, cell, nx, ny, cell_offsets, cell_items, mid, chunk_lane,
                        chunk_s0, chunk_s1, box, u, gcum, px, py, heading, base, length, offsets,
                        ids_arr, cdf_arr, out_chunk, out_s, out_xy, out_heading)


cdef inline bint _box_cells(const f64[::1] cell_origin, double cell, Py_ssize_t nx, Py_ssize_t ny,
                            const f64[::1] box, Py_ssize_t* r) noexcept nogil:
    """Grid cells that meet `box`: r = [ix0, iy0, ix1, iy1] (inclusive); False when none."""
    r[0] = max(0, <Py_ssize_t>((box[0] - cell_origin[0]) // cell))
    r[1] = max(0, <Py_ssize_t>((box[1] - cell_origin[1]) // cell))
    r[2] = min(nx - 1, <Py_ssize_t>((box[2] - cell_origin[0]) // cell))
    r[3] = min(ny - 1, <Py_ssize_t>((box[3] - cell_origin[1]) // cell))
    return r[2] >= r[0] and r[3] >= r[1]


cdef Py_ssize_t _box_count(const f64[::1] cell_origin, double cell, Py_ssize_t nx, Py_ssize_t ny,
                           const i64[::1] cell_offsets, const f64[::1] box) noexcept:
    """Number of items in the cells that meet `box` (an upper bound of the chunks inside)."""
    cdef Py_ssize_t r[4]
    cdef Py_ssize_t i, k = 0
    if not _box_cells(cell_origin, cell, nx, ny, box, r):
        return 0
    for i in range(r[0], r[2] + 1):
        k += cell_offsets[i * ny + r[3] + 1] - cell_offsets[i * ny + r[1]]
    return k


cdef Py_ssize_t _chunk_poses(
    const f64[::1] cell_origin, double cell, Py_ssize_t nx, Py_ssize_t ny,
    const i64[::1] cell_offsets, const i64[::1] cell_items, const f64[:, ::1] mid,
    const i64[::1] chunk_lane, const f64[::1] chunk_s0, const f64[::1] chunk_s1,
    const f64[::1] box, const f64[:, ::1] u,
    const f64[::1] gcum, const f64[::1] px, const f64[::1] py, const f64[::1] heading,
    const f64[::1] base, const f64[::1] length, const i64[::1] offsets,
    i64[::1] ids, f64[::1] cdf,
    i64[::1] out_chunk, f64[::1] out_s, f64[:, ::1] out_xy, f64[::1] out_heading,
) noexcept nogil:
    """The body of `sample_chunk_poses` (ids, cdf: scratch of `_box_count` entries)."""
    cdef Py_ssize_t r[4]
    cdef Py_ssize_t i, c, q, n_ids = 0, m = 0, n = u.shape[0]
    cdef i64 lo, hi, md, ln, ch
    cdef double total = 0.0, g, target, f, x, y, s
    if not _box_cells(cell_origin, cell, nx, ny, box, r):
        return 0
    for i in range(r[0], r[2] + 1):
        for c in range(cell_offsets[i * ny + r[1]], cell_offsets[i * ny + r[3] + 1]):
            ch = cell_items[c]
            if box[0] <= mid[ch, 0] <= box[2] and box[1] <= mid[ch, 1] <= box[3]:
                ids[n_ids] = ch
                total += chunk_s1[ch] - chunk_s0[ch]
                cdf[n_ids] = total
                n_ids += 1
    if n_ids == 0:
        n = 0  # nothing in the box: draw nothing
    for q in range(n):
        target = u[q, 0] * total
        lo = 0
        hi = n_ids - 1
        while lo < hi:  # first chunk whose cumulative length exceeds target
            md = (lo + hi) >> 1
            if cdf[md] > target:
                hi = md
            else:
                lo = md + 1
        ch = ids[lo]
        s = chunk_s0[ch] + u[q, 1] * (chunk_s1[ch] - chunk_s0[ch])
        ln = chunk_lane[ch]
        g = base[ln] + s
        lo = _lane_piece(gcum, offsets, ln, g)
        f = (g - gcum[lo]) / (gcum[lo + 1] - gcum[lo])
        x = px[lo] + f * (px[lo + 1] - px[lo])
        y = py[lo] + f * (py[lo + 1] - py[lo])
        if box[0] <= x <= box[2] and box[1] <= y <= box[3]:
            out_chunk[m] = ch
            out_s[m] = s
            out_xy[m, 0] = x
            out_xy[m, 1] = y
            out_heading[m] = heading[lo]
            m += 1
    return m


cdef inline void _lane_point(
    const f64[::1] gcum, const f64[::1] px, const f64[::1] py, const f64[::1] base,
    const f64[::1] length, const i64[::1] offsets, i64 ln, double s, double* x, double* y,
) noexcept nogil:
    """Point at arc length s (clamped) on lane ln (see `lane_points`)."""
    cdef i64 lo = offsets[ln], hi = offsets[ln + 1] - 2, md
    cdef double g, f
    if s < 0.0:
        s = 0.0
    if s > length[ln]:
        s = length[ln]
    g = base[ln] + s
    while lo < hi:
        md = (lo + hi + 1) >> 1
        if gcum[md] <= g:
            lo = md
        else:
            hi = md - 1
    f = (g - gcum[lo]) / (gcum[lo + 1] - gcum[lo])
    x[0] = px[lo] + f * (px[lo + 1] - px[lo])
    y[0] = py[lo] + f * (py[lo + 1] - py[lo])


def route_waypoints_batch(
    const i64[:, ::1] lanes, const f64[:, ::1] s_start, const f64[:, ::1] s_end, const f64[:, ::1] t_end,
    const f64[:, ::1] times, const f64[::1] speed,
    const f64[::1] gcum, const f64[::1] px, const f64[::1] py, const f64[::1] base,
    const f64[::1] length, const i64[::1] offsets,
    cnp.float32_t[:, :, ::1] out_xy, cnp.int32_t[::1] out_count,
):
    """Waypoints at route times (the NumPy path is `testing.spawn_reference.batch_waypoints_reference`).

    Args:
        lanes, s_start, s_end, t_end: (A, n) route pieces (`maps.routing.RouteBatch`).
        times: (A, K) increasing waypoint times [s].
        speed: (L,) lane speed limits [m/s].
        gcum, px, py, base, length, offsets: lane point tables (`RouteTables`).
        out_xy: (A, K, 2) float32 output [m], padded with the last valid waypoint.
        out_count: (A,) int32 output, valid waypoints (>= 1: a route shorter than the first gap
            gets its end as the single waypoint).
    """
    with nogil:
        _waypoints_batch(lanes, s_start, s_end, t_end, times, speed, gcum, px, py, base, length,
                         offsets, out_xy, out_count)


cdef void _waypoints_batch(
    const i64[:, ::1] lanes, const f64[:, ::1] s_start, const f64[:, ::1] s_end, const f64[:, ::1] t_end,
    const f64[:, ::1] times, const f64[::1] speed,
    const f64[::1] gcum, const f64[::1] px, const f64[::1] py, const f64[::1] base,
    const f64[::1] length, const i64[::1] offsets,
    cnp.float32_t[:, :, ::1] out_xy, cnp.int32_t[::1] out_count,
) noexcept nogil:
    """The body of `route_waypoints_batch`."""
    cdef Py_ssize_t a, k, p, n = lanes.shape[1], K = times.shape[1]
    cdef double total, t, t_before, s, x = 0.0, y = 0.0
    cdef int count
    cdef i64 ln
    for a in range(lanes.shape[0]):
        total = t_end[a, n - 1]
        count = 0
        for k in range(K):
            if times[a, k] <= total:
                count += 1
        if count < 1:
            count = 1
        out_count[a] = count
        p = 0
        for k in range(K):
            if k >= count:
                out_xy[a, k, 0] = out_xy[a, count - 1, 0]
                out_xy[a, k, 1] = out_xy[a, count - 1, 1]
                continue
            t = times[a, k] if times[a, k] < total else total
            while p < n - 1 and t_end[a, p] < t:
                p += 1
            t_before = t_end[a, p - 1] if p > 0 else 0.0
            ln = lanes[a, p]
            if ln < 0:
                ln = 0
            s = s_start[a, p] + (t - t_before) * speed[ln]
            if s > s_end[a, p]:
                s = s_end[a, p]
            _lane_point(gcum, px, py, base, length, offsets, ln, s, &x, &y)
            out_xy[a, k, 0] = <cnp.float32_t>x
            out_xy[a, k, 1] = <cnp.float32_t>y


cdef class RouteKernel:
    """The route tables of one map (`maps.routing.RouteTables`) bound once as typed views, so
    a world reset pays no per-call argument conversion (`scenario.index.MapIndex.kernels`)."""

    cdef readonly object tables
    cdef const f64[::1] gcum, px, py, heading, base, length, speed
    cdef const i64[::1] offsets, succ_off, succ_idx, left, right
    cdef bint has_changes
    cdef object _lanes, _s0, _s1, _t_end, _change

    def __init__(self, tables):
        self.tables = tables
        self.gcum = tables.gcum
        self.px = tables.px
        self.py = tables.py
        self.heading = tables.heading
        self.base = tables.base
        self.length = tables.length
        self.speed = tables.speed
        self.offsets = tables.offsets
        self.succ_off = tables.succ_offsets
        self.succ_idx = tables.succ_index
        self.left = tables.change_left
        self.right = tables.change_right
        self.has_changes = bool(tables.has_changes)
        self._lanes = None

    def waypoints(self, const i64[::1] start_lane, const f64[::1] start_s, const f64[:, ::1] times,
                  u64 key, double p_change, double min_change, Py_ssize_t max_pieces,
                  cnp.float32_t[:, :, ::1] out_xy, cnp.int32_t[::1] out_count):
        """`walk_routes` (routes lasting times[:, -1] s) then `route_waypoints_batch` in one
        call, into out_xy (A, K, 2) and out_count (A,) (the first A rows). Same results as
        `maps.routing.sample_routes` + `batch_waypoints` with the same key. The route pieces
        live in scratch kept between calls: a walk writes every entry the waypoint pass reads
        (the pieces it takes, and t_end to the last column), so nothing needs clearing."""
        cdef Py_ssize_t a, n_agents = start_lane.shape[0], K = times.shape[1]
        cdef double s
        cdef bint changes = p_change > 0 and self.has_changes
        cdef cnp.npy_bool dead = False
        if n_agents == 0:
            return
        if self._lanes is None or self._lanes.shape[0] < n_agents or self._lanes.shape[1] != max_pieces:
            self._lanes = np.empty((n_agents, max_pieces), dtype=np.int64)
            self._s0 = np.empty((n_agents, max_pieces))
            self._s1 = np.empty((n_agents, max_pieces))
            self._t_end = np.empty((n_agents, max_pieces))
            self._change = np.empty((n_agents, max_pieces), dtype=bool)
        cdef i64[:, ::1] lanes = self._lanes
        cdef f64[:, ::1] s0 = self._s0, s1 = self._s1, t_end = self._t_end
        cdef cnp.npy_bool[:, ::1] change = self._change
        # the GIL stays held: Python threads sharing this map's kernel cannot interleave on
        # the scratch
        for a in range(n_agents):
            s = start_s[a]
            if s < 0.0:
                s = 0.0
            if s > self.length[start_lane[a]]:
                s = self.length[start_lane[a]]
            _walk_one(self.succ_off, self.succ_idx, self.left, self.right, self.length,
                      self.speed, start_lane[a], s, times[a, K - 1], key, a, p_change,
                      min_change, changes, lanes[a], s0[a], s1[a], change[a], t_end[a], &dead)
        _waypoints_batch(lanes[:n_agents], s0[:n_agents], s1[:n_agents], t_end[:n_agents],
                         times, self.speed, self.gcum, self.px, self.py, self.base,
                         self.length, self.offsets, out_xy, out_count)


cdef class ChunkKernel:
    """One `scenario.index.Chunks` set (and its map's route tables) bound once as typed views:
    `poses` is `sample_chunk_poses` without per-call argument conversion."""

    cdef const f64[::1] cell_origin, chunk_s0, chunk_s1
    cdef double cell
    cdef Py_ssize_t nx, ny
    cdef const i64[::1] cell_offsets, cell_items, chunk_lane
    cdef const f64[:, ::1] mid
    cdef RouteKernel r

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
        self.r = routes

    def poses(self, const f64[::1] box, const f64[:, ::1] u):
        """(lane, s, xy, heading, chunk) of the poses drawn with u (n, 2) in `box`."""
        cdef Py_ssize_t n = u.shape[0], m = 0, q
        cdef Py_ssize_t k = _box_count(self.cell_origin, self.cell, self.nx, self.ny,
                                       self.cell_offsets, box)
        chunk_arr = np.empty(n, dtype=np.int64)
        s_arr = np.empty(n)
        xy_arr = np.empty((n, 2))
        h_arr = np.empty(n)
        lane_arr = np.empty(n, dtype=np.int64)
        cdef i64[::1] chunk = chunk_arr, lane = lane_arr
        cdef RouteKernel r = self.r
        if n > 0 and k > 0:
            ids_arr = np.empty(k, dtype=np.int64)
            cdf_arr = np.empty(k)
            m = _chunk_poses(self.cell_origin, self.cell, self.nx, self.ny, self.cell_offsets,
                             self.cell_items, self.mid, self.chunk_lane, self.chunk_s0,
                             self.chunk_s1, box, u, r.gcum, r.px, r.py, r.heading, r.base,
                             r.length, r.offsets, ids_arr, cdf_arr, chunk, s_arr, xy_arr, h_arr)
            for q in range(m):
                lane[q] = self.chunk_lane[chunk[q]]
        return lane_arr[:m], s_arr[:m], xy_arr[:m], h_arr[:m], chunk_arr[:m]


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

    cdef Py_ssize_t query(self, const f64[::1] box, i64[::1] out) noexcept:
        """`CellIndex.query_box`: the sites whose midpoint lies in box, in cell order, into out
        (room for `_box_count` entries); returns their number."""
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
        out = np.empty(_box_count(self.cell_origin, self.cell, self.nx, self.ny, self.cell_offsets, box),
                       dtype=np.int64)
        return out[:self.query(box, out)]


def pedestrian_sites(CrossingKernel crosswalks, CrossingKernel crossings, const f64[::1] box):
    """Numbers of crosswalk and other crossing sites in `box` (`PedestrianSampler.sample`) and
    both index arrays: (n_cw, n_other, cw, other)."""
    cw = crosswalks.query_box(box)
    other = crossings.query_box(box)
    return len(cw), len(other), cw, other


def pedestrian_paths(
    CrossingKernel crosswalks, CrossingKernel crossings, const i64[::1] cw, const i64[::1] other,
    const f64[:, ::1] u, double share, double margin, double max_approach,
    const f64[:, ::1] veh_xy, const f64[::1] clear_r, const cnp.npy_bool[::1] still,
    f64[:, :, ::1] path, cnp.npy_bool[::1] ok,
):
    """The body of `scenario.pedestrians.PedestrianSampler.sample` after its draws (the NumPy
    code it replaces computed the same float64 operations in the same order): site choice,
    (n, 3, 2) paths (approach point, crossing start, crossing end) into `path`, and ok[i]
    when path i's first point keeps clear_r from every vehicle centre and no leg of it passes
    within clear_r of a vehicle with still set. u: (n, 9) the draws (columns 0-5 used here)."""
    cdef Py_ssize_t i, v, k, n = u.shape[0], n_cw = cw.shape[0], n_other = other.shape[0]
    cdef Py_ssize_t nv = veh_xy.shape[0]
    cdef bint use_cw, good
    cdef i64 site, pick, lim
    cdef double sx, sy, ex, ey, hw, dx, dy, norm, sdx, sdy, sh, ax, ay, bx, by, sign, tmp
    cdef double wx, wy, t, gx, gy, dd, r
    cdef CrossingKernel kk
    for i in range(n):
        use_cw = (u[i, 0] < share) if n_cw else False
        if use_cw:
            site = <i64>(u[i, 1] * n_cw)
            lim = n_cw
        else:
            site = <i64>(n_cw + u[i, 1] * n_other)
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
        # _paths
        dx = ex - sx
        dy = ey - sy
        norm = hypot(dx, dy)
        if norm < 1e-9:  # np.maximum(norm, 1e-9) (NaN stays NaN)
            norm = 1e-9
        dx = dx / norm
        dy = dy / norm
        sdx = -dy
        sdy = dx
        sh = hw * (2.0 * u[i, 2] - 1.0)
        if u[i, 3] < 0.5:
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
        sign = -1.0 if u[i, 4] < 0.5 else 1.0
        tmp = sign * max_approach * u[i, 5]
        path[i, 0, 0] = ax + sdx * tmp
        path[i, 0, 1] = ay + sdy * tmp
        path[i, 1, 0] = ax
        path[i, 1, 1] = ay
        path[i, 2, 0] = bx
        path[i, 2, 1] = by
        # _clear_of (first point) and _path_clear_of (every leg, still vehicles)
        good = True
        for v in range(nv):
            if not hypot(path[i, 0, 0] - veh_xy[v, 0], path[i, 0, 1] - veh_xy[v, 1]) >= clear_r[v]:
                good = False
                break
        if good:
            for v in range(nv):
                if not still[v]:
                    continue
                r = clear_r[v] * clear_r[v]
                for k in range(2):
                    dx = path[i, k + 1, 0] - path[i, k, 0]
                    dy = path[i, k + 1, 1] - path[i, k, 1]
                    wx = veh_xy[v, 0] - path[i, k, 0]
                    wy = veh_xy[v, 1] - path[i, k, 1]
                    dd = dx * dx + dy * dy
                    if dd < 1e-12:
                        dd = 1e-12
                    t = (wx * dx + wy * dy) / dd
                    t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
                    gx = wx - t * dx
                    gy = wy - t * dy
                    if not gx * gx + gy * gy >= r:
                        good = False
                        break
                if not good:
                    break
        ok[i] = good


def vehicle_sizes(const f64[:, ::1] u, const f64[::1] cdf, const f64[::1] length_tab,
                  const f64[::1] width_tab, double jitter, double max_width):
    """The body of `scenario.vehicles.VehicleSizeSampler.sample` after its (3, n) draw `u`:
    category = first cdf entry above u[0] (capped at the last), length and width scaled by
    1 - jitter + 2 jitter u[1] and u[2], width capped at max_width.

    Returns:
        length (n,) float64 [m], width (n,) float64 [m], category (n,) int64.
    """
    cdef Py_ssize_t i, c, n = u.shape[1], K = cdf.shape[0]
    cdef double a = 1.0 - jitter, b = 2.0 * jitter, w
    length_arr = np.empty(n)
    width_arr = np.empty(n)
    cat_arr = np.empty(n, dtype=np.int64)
    cdef f64[::1] length = length_arr, width = width_arr
    cdef i64[::1] cat = cat_arr
    for i in range(n):
        c = 0
        while c < K and cdf[c] <= u[0, i]:  # searchsorted(cdf, u, side="right")
            c += 1
        if c > K - 1:
            c = K - 1
        cat[i] = c
        length[i] = length_tab[c] * (a + b * u[1, i])
        w = width_tab[c] * (a + b * u[2, i])
        width[i] = w if w < max_width else max_width  # np.minimum (max_width is finite)
    return length_arr, width_arr, cat_arr


cdef inline double _wrap_angle(double a) noexcept nogil:
    """NumPy's (a + pi) % (2 pi) - pi (float remainder: fmod with the sign of the divisor)."""
    cdef double b = 6.283185307179586, mod = fmod(a + 3.141592653589793, b)
    if mod != 0.0:
        if mod < 0.0:
            mod = mod + b
    else:
        mod = 0.0
    return mod - 3.141592653589793


def aligned_candidates(
    const i64[::1] lane, const f64[::1] s, const f64[:, ::1] xy, const f64[::1] heading,
    const f64[::1] sin_h, const f64[::1] cos_h, const f64[::1] length, const f64[::1] width,
    const f64[:, ::1] u, const cnp.float32_t[::1] lane_width, const cnp.float32_t[::1] speed_limit,
    double lateral_noise, double heading_noise, double speed_lo, double speed_hi,
    f64[:, ::1] out,
):
    """The arithmetic of `PaperSpawner._aligned` for n candidate poses (the NumPy code it
    replaces evaluated the same float64 operations in the same order): lateral shift
    min(l, max(lane width - width, 0) / 2) (2 u[0] - 1) to the right of the pose (sin_h,
    cos_h: numpy's sin and cos of `heading`), heading noise h (2 u[1] - 1) wrapped into
    [-pi, pi), speed lo + (hi - lo) u[2] capped by the lane speed limit. Rows of `out`
    (n, 10): the spawner's agent columns (lane, s, x, y, heading, speed, length, width,
    parked = 0, on lane = 1)."""
    cdef Py_ssize_t i, n = lane.shape[0]
    cdef double lw, m, lat
    for i in range(n):
        lw = lane_width[lane[i]]
        m = lw - width[i]
        if m < 0.0:
            m = 0.0
        m = m / 2
        lat = (lateral_noise if lateral_noise < m else m) * (2 * u[0, i] - 1)
        out[i, 0] = <double>lane[i]
        out[i, 1] = s[i]
        out[i, 2] = xy[i, 0] + lat * sin_h[i]
        out[i, 3] = xy[i, 1] + lat * -cos_h[i]
        out[i, 4] = _wrap_angle(heading[i] + heading_noise * (2 * u[1, i] - 1))
        m = speed_lo + (speed_hi - speed_lo) * u[2, i]
        out[i, 5] = m if m < speed_limit[lane[i]] else <double>speed_limit[lane[i]]
        out[i, 6] = length[i]
        out[i, 7] = width[i]
        out[i, 8] = 0.0
        out[i, 9] = 1.0


def roadside_poses(
    const i64[::1] lane, const i64[::1] chunk, const f64[:, ::1] xy, const f64[::1] sin_h,
    const f64[::1] cos_h, const f64[::1] width, const cnp.float32_t[::1] lane_width,
    const f64[::1] edge, double curb_gap, double max_shoulder, double min_free,
    f64[:, ::1] out_xy, f64[::1] out_off, cnp.npy_bool[::1] out_fits,
):
    """`scenario.placement.roadside_offset` and `offset_right` for n roadside poses (same
    float64 operations): the right side `curb_gap` inside the road edge of the chunk, at most
    `max_shoulder` beyond the lane border, offset >= 0; out_fits: the vehicle leaves at least
    `min_free` m of its lane free."""
    cdef Py_ssize_t i, n = lane.shape[0]
    cdef double lw, rs, b, off
    for i in range(n):
        lw = lane_width[lane[i]]
        rs = edge[chunk[i]] - curb_gap
        b = lw / 2 + max_shoulder
        if b < rs:
            rs = b
        off = rs - width[i] / 2
        if off < 0.0:
            off = 0.0
        out_off[i] = off
        out_fits[i] = off - width[i] / 2 + lw / 2 >= min_free
        out_xy[i, 0] = xy[i, 0] + off * sin_h[i]
        out_xy[i, 1] = xy[i, 1] + off * -cos_h[i]


def bimodal_uniform(const f64[:, ::1] u, const f64[::1] lo, const f64[::1] hi, Py_ssize_t c,
                    double c_lo, double c_hi, double p_c, Py_ssize_t a, double a_lo, double a_hi,
                    double p_a):
    """The body of `scenario.conditioning.ConditioningSampler.sample` after its (n, C + 2) draw:
    coefficient k of agent i is lo_k + (hi_k - lo_k) u[i, k], where columns c and a take the
    low ranges (c_lo, c_hi), (a_lo, a_hi) when u[i, C] < p_c, u[i, C + 1] < p_a.

    Returns:
        (n, C) float32.
    """
    cdef Py_ssize_t i, k, n = u.shape[0], C = lo.shape[0]
    cdef double l, h
    out_arr = np.empty((n, C), dtype=np.float32)
    cdef cnp.float32_t[:, ::1] out = out_arr
    for i in range(n):
        for k in range(C):
            l = lo[k]
            h = hi[k]
            if k == c and u[i, C] < p_c:
                l = c_lo
                h = c_hi
            if k == a and u[i, C + 1] < p_a:
                l = a_lo
                h = a_hi
            out[i, k] = <cnp.float32_t>(l + (h - l) * u[i, k])
    return out_arr
