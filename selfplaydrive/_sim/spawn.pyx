# cython: language_level=3
"""Spawner kernels (paper section 2.2): agent and static-vehicle placement, route walks and
waypoints, pedestrians, and their building blocks.

They run once per world reset from `selfplaydrive.scenario` and `selfplaydrive.maps.routing`.
The kernels that draw random numbers take them straight from the world's
`numpy.random.Generator` (its bit generator's `next_double`: the values `rng.random` would
give), one candidate at a time, so a reset computes only the candidates it tries. NumPy
references with the same semantics (and the same draws) are in
`selfplaydrive/testing/spawn_reference.py` and the tests compare them bit for bit.
"""

import numpy as np

cimport numpy as cnp
from cpython.pycapsule cimport PyCapsule_GetPointer
from libc.math cimport cos, fabs, fmod, hypot, sin
from libc.stdlib cimport free, malloc
from numpy.random cimport bitgen_t

cnp.import_array()

ctypedef cnp.float64_t f64
ctypedef cnp.int64_t i64
ctypedef cnp.uint64_t u64


cdef void* _alloc(size_t nbytes) except NULL:
    """malloc that raises MemoryError (at least one byte, so zero-size scratch is valid)."""
    cdef void* p = malloc(nbytes if nbytes > 0 else 1)
    if p == NULL:
        raise MemoryError(f"spawn kernel scratch of {nbytes} bytes")
    return p


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
            # a draw is hashed only where it decides something (counter-based: skipping one
            # changes no other)
            if left[lane] >= 0 and right[lane] >= 0:
                target = _change_target(left, right, lane, hash_uniform(key, agent, 3 * step + 1))
            else:
                target = _change_target(left, right, lane, 0.0)
            lc = (target >= 0 and not prev and L - s_in >= min_change
                  and hash_uniform(key, agent, 3 * step) < p_change)
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
        if deg > 1 and not lc:
            k = <i64>(hash_uniform(key, agent, 3 * step + 2) * deg)
            if k > deg - 1:
                k = deg - 1
            nxt = succ_idx[succ_off[lane] + k]
        elif deg > 0:
            nxt = succ_idx[succ_off[lane]]
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
    """The route tables of one map (`maps.routing.RouteTables`) and its lanes' widths and speed
    limits bound once as typed views, so a world reset pays no per-call argument conversion
    (`scenario.index.MapIndex.kernels`). hsin, hcos: sine and cosine of each centreline
    piece's heading (NumPy's, computed once)."""

    cdef readonly object tables
    cdef const f64[::1] gcum, px, py, heading, base, length, speed, hsin, hcos
    cdef const cnp.float32_t[::1] lane_width, speed_limit
    cdef const i64[::1] offsets, succ_off, succ_idx, left, right
    cdef bint has_changes
    cdef object _lanes, _s0, _s1, _t_end, _change

    def __init__(self, tables, lane_width, speed_limit):
        """tables: `RouteTables`; lane_width, speed_limit: (L,) `Lanes.width` and
        `Lanes.speed_limit` [m, m/s] of the same map."""
        if len(lane_width) != len(tables.length) or len(speed_limit) != len(tables.length):
            raise ValueError(
                f"RouteKernel: lane_width and speed_limit need one entry per lane ({len(tables.length)}), "
                f"got {len(lane_width)} and {len(speed_limit)}"
            )
        self.tables = tables
        self.hsin = np.sin(tables.heading)
        self.hcos = np.cos(tables.heading)
        self.lane_width = np.ascontiguousarray(lane_width, dtype=np.float32)
        self.speed_limit = np.ascontiguousarray(speed_limit, dtype=np.float32)
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
        self._waypoints(start_lane, start_s, times, key, p_change, min_change, max_pieces, out_xy,
                        out_count)

    def draw_waypoints(self, object rng, const i64[::1] start_lane, const f64[::1] start_s,
                       Py_ssize_t max_waypoints, double spacing, double jitter, double p_change,
                       double min_change, Py_ssize_t max_pieces, cnp.float32_t[:, :, ::1] out_xy,
                       cnp.int32_t[::1] out_count):
        """`waypoints` with its draws taken from `rng`: the times of
        `maps.routing.waypoint_times(rng, A, max_waypoints, spacing, jitter)` (cumulative sums of
        spacing * U(1 - jitter, 1 + jitter), computed as `Generator.uniform` does), then the key
        `rng.integers(0, 2**63)` (the top 63 of the next 64 random bits: what NumPy's bounded
        integer draw gives for a power-of-two range); the same values those calls give."""
        cdef Py_ssize_t a, k, n_agents = start_lane.shape[0]
        cdef bitgen_t* bg = _bitgen(rng)
        cdef double lo = 1.0 - jitter, span = (1.0 + jitter) - (1.0 - jitter), acc
        cdef u64 key
        times_arr = np.empty((n_agents, max_waypoints))
        cdef f64[:, ::1] times = times_arr
        with rng.bit_generator.lock:
            for a in range(n_agents):
                acc = 0.0
                for k in range(max_waypoints):
                    acc = acc + spacing * (lo + span * bg.next_double(bg.state))
                    times[a, k] = acc
            key = bg.next_uint64(bg.state) >> 1
        self._waypoints(start_lane, start_s, times, key, p_change, min_change, max_pieces, out_xy,
                        out_count)

    cdef int _waypoints(self, const i64[::1] start_lane, const f64[::1] start_s, const f64[:, ::1] times,
                        u64 key, double p_change, double min_change, Py_ssize_t max_pieces,
                        cnp.float32_t[:, :, ::1] out_xy, cnp.int32_t[::1] out_count) except -1:
        """The body of `waypoints`."""
        cdef Py_ssize_t a, n_agents = start_lane.shape[0], K = times.shape[1]
        cdef double s
        cdef bint changes = p_change > 0 and self.has_changes
        cdef cnp.npy_bool dead = False
        if n_agents == 0:
            return 0
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
        return 0


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
    """One `scenario.index.Chunks` set (and its map's route tables) bound once as typed views:
    `gather` lists the chunks whose midpoint lies in a box with their cumulative lengths, `pose`
    turns two uniforms into a pose on them; `poses` runs both for n draws (its NumPy twin is
    `testing.spawn_reference.sample_on_chunks_reference`)."""

    cdef const f64[::1] cell_origin, chunk_s0, chunk_s1, edge, sorted_len
    cdef double cell
    cdef Py_ssize_t nx, ny
    cdef const i64[::1] cell_offsets, cell_items, chunk_lane
    cdef const f64[:, ::1] mid, sorted_mid
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


cdef inline i64 _size(const f64[::1] cdf, const f64[::1] length_tab, const f64[::1] width_tab,
                      double jitter, double max_width, double u0, double u1, double u2,
                      double* length, double* width) noexcept nogil:
    """One vehicle size: category = first cdf entry above u0 (capped at the last), length and
    width scaled by 1 - jitter + 2 jitter u1 and u2, width capped at max_width; returns the
    category."""
    cdef i64 c = 0, K = cdf.shape[0]
    cdef double a = 1.0 - jitter, b = 2.0 * jitter, w
    while c < K and cdf[c] <= u0:  # searchsorted(cdf, u0, side="right")
        c += 1
    if c > K - 1:
        c = K - 1
    length[0] = length_tab[c] * (a + b * u1)
    w = width_tab[c] * (a + b * u2)
    width[0] = w if w < max_width else max_width  # np.minimum (max_width is finite)
    return c


def vehicle_sizes(const f64[:, ::1] u, const f64[::1] cdf, const f64[::1] length_tab,
                  const f64[::1] width_tab, double jitter, double max_width):
    """The body of `scenario.vehicles.VehicleSizeSampler.sample` after its (3, n) draw `u`
    (`_size` of each column).

    Returns:
        length (n,) float64 [m], width (n,) float64 [m], category (n,) int64.
    """
    cdef Py_ssize_t i, n = u.shape[1]
    length_arr = np.empty(n)
    width_arr = np.empty(n)
    cat_arr = np.empty(n, dtype=np.int64)
    cdef f64[::1] length = length_arr, width = width_arr
    cdef i64[::1] cat = cat_arr
    for i in range(n):
        cat[i] = _size(cdf, length_tab, width_tab, jitter, max_width, u[0, i], u[1, i], u[2, i],
                       &length[i], &width[i])
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


# columns of the spawner's agent rows (`scenario.spawner.AGENT_COLUMNS`)
cdef enum:
    COL_LANE = 0
    COL_S = 1
    COL_X = 2
    COL_Y = 3
    COL_HEADING = 4
    COL_SPEED = 5
    COL_LENGTH = 6
    COL_WIDTH = 7
    COL_PARKED = 8
    COL_ON_LANE = 9
    NCOL = 10


cdef inline void _aligned_row(
    i64 lane, double s, double x, double y, double heading, double sin_h, double cos_h,
    double length, double width, double u0, double u1, double u2, double lane_width,
    double speed_limit, double lateral_noise, double heading_noise, double speed_lo,
    double speed_hi, double* out,
) noexcept nogil:
    """The agent row (`NCOL` columns) of an aligned candidate: lateral shift
    min(l, max(lane width - width, 0) / 2) (2 u0 - 1) to the right of the pose (sin_h, cos_h:
    NumPy's sine and cosine of `heading`), heading noise h (2 u1 - 1) wrapped into [-pi, pi),
    speed lo + (hi - lo) u2 capped by the lane speed limit, parked 0, on lane 1."""
    cdef double m = lane_width - width, lat
    if m < 0.0:
        m = 0.0
    m = m / 2
    lat = (lateral_noise if lateral_noise < m else m) * (2 * u0 - 1)
    out[COL_LANE] = <double>lane
    out[COL_S] = s
    out[COL_X] = x + lat * sin_h
    out[COL_Y] = y + lat * -cos_h
    out[COL_HEADING] = _wrap_angle(heading + heading_noise * (2 * u1 - 1))
    m = speed_lo + (speed_hi - speed_lo) * u2
    out[COL_SPEED] = m if m < speed_limit else speed_limit
    out[COL_LENGTH] = length
    out[COL_WIDTH] = width
    out[COL_PARKED] = 0.0
    out[COL_ON_LANE] = 1.0


def aligned_candidates(
    const i64[::1] lane, const f64[::1] s, const f64[:, ::1] xy, const f64[::1] heading,
    const f64[::1] sin_h, const f64[::1] cos_h, const f64[::1] length, const f64[::1] width,
    const f64[:, ::1] u, const cnp.float32_t[::1] lane_width, const cnp.float32_t[::1] speed_limit,
    double lateral_noise, double heading_noise, double speed_lo, double speed_hi,
    f64[:, ::1] out,
):
    """`_aligned_row` (the aligned-agent arithmetic of `Placer.agents`) for n candidate poses
    with draws u (3, n); rows into out (n, 10)."""
    cdef Py_ssize_t i, n = lane.shape[0]
    for i in range(n):
        _aligned_row(lane[i], s[i], xy[i, 0], xy[i, 1], heading[i], sin_h[i], cos_h[i], length[i],
                     width[i], u[0, i], u[1, i], u[2, i], lane_width[lane[i]], speed_limit[lane[i]],
                     lateral_noise, heading_noise, speed_lo, speed_hi, &out[i, 0])


cdef inline bint _roadside(double x, double y, double sin_h, double cos_h, double width,
                           double lane_width, double edge, double curb_gap, double max_shoulder,
                           double min_free, double* out) noexcept nogil:
    """`scenario.placement.roadside_offset` and `offset_right` for one vehicle of `width` parked
    beside the pose (x, y) (same float64 operations): the right side `curb_gap` inside the road
    edge at distance `edge`, at most `max_shoulder` beyond the lane border, offset >= 0.
    out = (x, y, offset); returns whether the vehicle leaves `min_free` m of its lane free."""
    cdef double rs = edge - curb_gap, b = lane_width / 2 + max_shoulder, off
    if b < rs:
        rs = b
    off = rs - width / 2
    if off < 0.0:
        off = 0.0
    out[0] = x + off * sin_h
    out[1] = y + off * -cos_h
    out[2] = off
    return off - width / 2 + lane_width / 2 >= min_free


def roadside_poses(
    const i64[::1] lane, const i64[::1] chunk, const f64[:, ::1] xy, const f64[::1] sin_h,
    const f64[::1] cos_h, const f64[::1] width, const cnp.float32_t[::1] lane_width,
    const f64[::1] edge, double curb_gap, double max_shoulder, double min_free,
    f64[:, ::1] out_xy, f64[::1] out_off, cnp.npy_bool[::1] out_fits,
):
    """`_roadside` for n roadside poses (edge of each pose's chunk): centres, offsets and
    whether each vehicle leaves `min_free` m of its lane free."""
    cdef Py_ssize_t i, n = lane.shape[0]
    cdef double o[3]
    for i in range(n):
        out_fits[i] = _roadside(xy[i, 0], xy[i, 1], sin_h[i], cos_h[i], width[i], lane_width[lane[i]],
                                edge[chunk[i]], curb_gap, max_shoulder, min_free, o)
        out_xy[i, 0] = o[0]
        out_xy[i, 1] = o[1]
        out_off[i] = o[2]


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


# -- agent and static-vehicle placement ---------------------------------------------------------

cdef bitgen_t* _bitgen(object rng) except NULL:
    """The C bit generator of a `numpy.random.Generator`: `next_double` continues its stream
    exactly as `rng.random` does, so a kernel can draw lazily, one candidate at a time. Callers
    hold `rng.bit_generator.lock` while drawing."""
    return <bitgen_t*>PyCapsule_GetPointer(rng.bit_generator.capsule, "BitGenerator")


cdef inline void _draw(bitgen_t* bg, double* u, Py_ssize_t n) noexcept nogil:
    """n uniforms in [0, 1) into u (the next n values of `rng.random`)."""
    cdef Py_ssize_t i
    for i in range(n):
        u[i] = bg.next_double(bg.state)


cdef void* _field(object sc, str name, int typenum, Py_ssize_t size) except NULL:
    """Data pointer of the output array `sc.name` (a `Scenario` or `PedestrianBatch` field)
    after checking its dtype, layout and size."""
    arr = getattr(sc, name)
    if (not isinstance(arr, np.ndarray) or cnp.PyArray_TYPE(<cnp.ndarray>arr) != typenum
            or not cnp.PyArray_IS_C_CONTIGUOUS(<cnp.ndarray>arr)
            or not cnp.PyArray_ISWRITEABLE(<cnp.ndarray>arr) or cnp.PyArray_SIZE(<cnp.ndarray>arr) < size):
        raise ValueError(
            f"{type(sc).__name__}.{name} must be a writable C-contiguous {cnp.PyArray_DescrFromType(typenum)} "
            f"array of at least {size} entries, got {type(arr).__name__} "
            f"{getattr(arr, 'dtype', '')} {getattr(arr, 'shape', '')}"
        )
    return cnp.PyArray_DATA(<cnp.ndarray>arr)


cdef inline bint _spaced(const double* rows, Py_ssize_t n, double x, double y, double lim) noexcept nogil:
    """Whether (x, y) keeps at least `lim` from the centres of the first n agent rows."""
    cdef Py_ssize_t j
    cdef double dx, dy
    for j in range(n):
        dx = x - rows[j * NCOL + COL_X]
        dy = y - rows[j * NCOL + COL_Y]
        if dx * dx + dy * dy < lim * lim:
            return False
    return True


cdef inline bint _boxes_meet(double ax, double ay, double ac, double a_s, double ahx, double ahy,
                             double bx, double by, double bc, double b_s, double bhx,
                             double bhy) noexcept nogil:
    """Whether two rectangles overlap (separating-axis test): centres (ax, ay), (bx, by), long
    axes (cos, sin) = (ac, a_s), (bc, b_s), half lengths ahx, bhx and half widths ahy, bhy."""
    cdef double dx = bx - ax, dy = by - ay
    cdef double cc = fabs(ac * bc + a_s * b_s), cs = fabs(ac * b_s - a_s * bc)
    if fabs(dx * ac + dy * a_s) > ahx + bhx * cc + bhy * cs:
        return False
    if fabs(dy * ac - dx * a_s) > ahy + bhx * cs + bhy * cc:
        return False
    if fabs(dx * bc + dy * b_s) > bhx + ahx * cc + ahy * cs:
        return False
    if fabs(dy * bc - dx * b_s) > bhy + ahx * cs + ahy * cc:
        return False
    return True


def boxes_meet(double ax, double ay, double ah, double al, double aw,
               double bx, double by, double bh, double bl, double bw):
    """Whether box a (centre, heading [rad], length, width [m]) overlaps box b (`_boxes_meet`;
    for tests)."""
    return _boxes_meet(ax, ay, cos(ah), sin(ah), al / 2, aw / 2, bx, by, cos(bh), sin(bh), bl / 2, bw / 2)


cdef class SizeTable:
    """A `scenario.vehicles.VehicleSizeSampler` bound as typed views: `_size` per draw."""

    cdef const f64[::1] cdf, length, width
    cdef double jitter, max_width

    def __init__(self, sampler):
        self.cdf = np.ascontiguousarray(sampler._cdf, dtype=np.float64)
        self.length = np.ascontiguousarray(sampler.length, dtype=np.float64)
        self.width = np.ascontiguousarray(sampler.width, dtype=np.float64)
        self.jitter = float(sampler.jitter)
        self.max_width = float(sampler.max_width)

    cdef inline void draw(self, const double* u, double* length, double* width) noexcept:
        """Size of one vehicle from the uniforms u[0:3]."""
        _size(self.cdf, self.length, self.width, self.jitter, self.max_width, u[0], u[1], u[2],
              length, width)


cdef class Placer:
    """Agent and static-vehicle placement of `scenario.spawner.PaperSpawner` (paper section
    2.2) with the spawner's settings bound once. Candidates are drawn one at a time from the
    world's generator (`rng.random` values, in order) and accepted greedily, so only the
    candidates tried are computed; the NumPy references are
    `testing.spawn_reference.place_agents_reference` and `place_statics_reference`.

    Args:
        sizes, static_sizes: `VehicleSizeSampler` of agents and of static vehicles.
        min_agent_distance: Least distance between agent centres [m].
        first_round_candidates: Aligned candidates per wanted agent whose draws are taken in
            one block up front.
        candidates_per_agent: Candidates per wanted agent at most (parked and aligned).
        static_candidates_per_vehicle: Candidates per wanted static vehicle.
        lateral_noise, heading_noise, speed_lo, speed_hi: Aligned-agent noise [m, rad] and
            initial speed range [m/s].
        curb_gap, max_shoulder: Roadside placement [m] (`_roadside`).
        static_gap: Clearance [m] of static vehicles to every other vehicle.
        min_free_lane_width: Lane width [m] a static vehicle leaves free.
        clear_ahead, headway: A static vehicle stays out of the lane space ahead of each
            agent up to clear_ahead [m] plus the distance the agent covers in `headway` [s].
    """

    cdef SizeTable sizes, static_sizes
    cdef double min_dist, lateral_noise, heading_noise, speed_lo, speed_hi, curb_gap, max_shoulder
    cdef double static_gap, min_free, clear_ahead, headway
    cdef Py_ssize_t first, per_agent, per_static

    def __init__(self, sizes, static_sizes, double min_agent_distance, Py_ssize_t first_round_candidates,
                 Py_ssize_t candidates_per_agent, Py_ssize_t static_candidates_per_vehicle,
                 double lateral_noise, double heading_noise, double speed_lo, double speed_hi,
                 double curb_gap, double max_shoulder, double static_gap, double min_free_lane_width,
                 double clear_ahead, double headway):
        self.sizes = SizeTable(sizes)
        self.static_sizes = SizeTable(static_sizes)
        self.min_dist = min_agent_distance
        self.first = min(first_round_candidates, candidates_per_agent)
        self.per_agent = candidates_per_agent
        self.per_static = static_candidates_per_vehicle
        self.lateral_noise = lateral_noise
        self.heading_noise = heading_noise
        self.speed_lo = speed_lo
        self.speed_hi = speed_hi
        self.curb_gap = curb_gap
        self.max_shoulder = max_shoulder
        self.static_gap = static_gap
        self.min_free = min_free_lane_width
        self.clear_ahead = clear_ahead
        self.headway = headway

    def agents(self, ChunkKernel spawn, ChunkKernel roadside, object rng, const f64[::1] box,
               Py_ssize_t want, Py_ssize_t n_parked, object sc):
        """Place up to `want` agents in `box` and fill the agent slots of `sc` (a `Scenario`).

        Parked first: up to n_parked at roadside spots (candidate draws u[0:5]: chunk, arc
        length, size), then aligned agents on the spawn chunks until `want` in all (draws
        u[0:8]: chunk, arc length, size, lateral shift, heading noise, speed); a candidate is
        accepted when its centre keeps `min_agent_distance` from every agent accepted before.
        Parked agents try n_parked * candidates_per_agent candidates, aligned ones
        need * candidates_per_agent, the first need * first_round_candidates of them drawn as
        one block. A candidate outside `box` is skipped (its draws are spent). Finally the
        agents are shuffled over the slots (Fisher-Yates from the last slot down, one draw
        each).

        Returns:
            (n agents placed, how many of them parked, (n,) int64 route start lane,
            (n,) float64 route start arc length [m]), both in slot order.
        """
        if want < 1 or not 0 <= n_parked <= want:
            raise ValueError(f"Placer.agents: need want >= 1 and 0 <= n_parked <= want, got {want}, {n_parked}")
        cdef RouteKernel r = spawn.r
        cdef bitgen_t* bg = _bitgen(rng)
        cdef Py_ssize_t k_r = roadside.count(box) if n_parked > 0 else 0, k_s = spawn.count(box)
        cdef Py_ssize_t got = 0, parked, need, block = 0, j, i, n_ids
        cdef double lim = self.min_dist, near = self.min_dist - self.lateral_noise - 1e-6
        cdef double u[8]
        cdef double o[3]
        cdef double* uu
        cdef Pose p
        cdef double L, W, lw
        cdef Py_ssize_t tmp
        cdef cnp.npy_bool* valid = <cnp.npy_bool*>_field(sc, "agent_valid", cnp.NPY_BOOL, want)
        cdef float* xy = <float*>_field(sc, "agent_xy", cnp.NPY_FLOAT32, 2 * want)
        cdef float* heading = <float*>_field(sc, "agent_heading", cnp.NPY_FLOAT32, want)
        cdef float* speed = <float*>_field(sc, "agent_speed", cnp.NPY_FLOAT32, want)
        cdef float* length = <float*>_field(sc, "agent_length", cnp.NPY_FLOAT32, want)
        cdef float* width = <float*>_field(sc, "agent_width", cnp.NPY_FLOAT32, want)
        cdef cnp.npy_bool* parked_out = <cnp.npy_bool*>_field(sc, "agent_parked", cnp.NPY_BOOL, want)
        cdef cnp.int32_t* lane_out = <cnp.int32_t*>_field(sc, "agent_lane", cnp.NPY_INT32, want)
        cdef double* rows = <double*>_alloc(want * NCOL * sizeof(double))
        cdef Py_ssize_t* order = NULL
        cdef i64* ids = NULL
        cdef f64* cdf = NULL
        cdef double* buf = NULL
        try:
            order = <Py_ssize_t*>_alloc(want * sizeof(Py_ssize_t))
            ids = <i64*>_alloc((k_r if k_r > k_s else k_s) * sizeof(i64))
            cdf = <f64*>_alloc((k_r if k_r > k_s else k_s) * sizeof(f64))
            buf = <double*>_alloc(want * self.first * 8 * sizeof(double))
            with rng.bit_generator.lock:
                # parked agents at roadside spots
                n_ids = roadside.gather(box, ids, cdf) if k_r > 0 else 0
                for j in range(n_parked * self.per_agent if n_ids > 0 else 0):
                    _draw(bg, u, 5)
                    if not roadside.pose(ids, cdf, n_ids, box, u[0], u[1], &p):
                        continue
                    self.sizes.draw(&u[2], &L, &W)
                    lw = r.lane_width[p.lane]
                    _roadside(p.x, p.y, r.hsin[p.piece], r.hcos[p.piece], W, lw, roadside.edge[p.chunk],
                              self.curb_gap, self.max_shoulder, 0.0, o)
                    if not _spaced(rows, got, o[0], o[1], lim):
                        continue
                    uu = rows + got * NCOL
                    uu[COL_LANE] = <double>p.lane
                    uu[COL_S] = p.s
                    uu[COL_X] = o[0]
                    uu[COL_Y] = o[1]
                    uu[COL_HEADING] = r.heading[p.piece]
                    uu[COL_SPEED] = 0.0
                    uu[COL_LENGTH] = L
                    uu[COL_WIDTH] = W
                    uu[COL_PARKED] = 1.0
                    uu[COL_ON_LANE] = 1.0 if o[2] <= lw / 2 else 0.0
                    got += 1
                    if got >= n_parked:
                        break
                parked = got
                # aligned agents on the spawn chunks
                need = want - parked
                n_ids = spawn.gather(box, ids, cdf) if k_s > 0 and need > 0 else 0
                if n_ids > 0:
                    block = need * self.first
                    _draw(bg, buf, block * 8)
                for j in range(need * self.per_agent if n_ids > 0 else 0):
                    if j < block:
                        uu = buf + j * 8
                    else:
                        _draw(bg, u, 8)
                        uu = u
                    if not spawn.pose(ids, cdf, n_ids, box, uu[0], uu[1], &p):
                        continue
                    # the lateral shift moves the centre at most lateral_noise: a pose that
                    # close to an agent is rejected for sure, before its size and noise
                    if near > 0.0 and not _spaced(rows, got, p.x, p.y, near):
                        continue
                    self.sizes.draw(&uu[2], &L, &W)
                    _aligned_row(p.lane, p.s, p.x, p.y, r.heading[p.piece], r.hsin[p.piece], r.hcos[p.piece],
                                 L, W, uu[5], uu[6], uu[7], r.lane_width[p.lane], r.speed_limit[p.lane],
                                 self.lateral_noise, self.heading_noise, self.speed_lo, self.speed_hi,
                                 rows + got * NCOL)
                    if not _spaced(rows, got, rows[got * NCOL + COL_X], rows[got * NCOL + COL_Y], lim):
                        continue
                    got += 1
                    if got >= want:
                        break
                # shuffle parked and aligned agents over the slots
                for i in range(got):
                    order[i] = i
                for i in range(got - 1, 0, -1):
                    j = <Py_ssize_t>(bg.next_double(bg.state) * (i + 1))
                    if j > i:
                        j = i
                    tmp = order[i]
                    order[i] = order[j]
                    order[j] = tmp
            lane_arr = np.empty(got, dtype=np.int64)
            s_arr = np.empty(got)
            for i in range(got):
                uu = rows + order[i] * NCOL
                valid[i] = True
                xy[2 * i] = <float>uu[COL_X]
                xy[2 * i + 1] = <float>uu[COL_Y]
                heading[i] = <float>uu[COL_HEADING]
                speed[i] = <float>uu[COL_SPEED]
                length[i] = <float>uu[COL_LENGTH]
                width[i] = <float>uu[COL_WIDTH]
                parked_out[i] = uu[COL_PARKED] != 0.0
                lane_out[i] = <cnp.int32_t>uu[COL_LANE] if uu[COL_ON_LANE] != 0.0 else -1
                (<i64*>cnp.PyArray_DATA(lane_arr))[i] = <i64>uu[COL_LANE]
                (<f64*>cnp.PyArray_DATA(s_arr))[i] = uu[COL_S]
        finally:
            free(rows)
            free(order)
            free(ids)
            free(cdf)
            free(buf)
        return got, parked, lane_arr, s_arr

    def statics(self, ChunkKernel roadside, object rng, const f64[::1] box, Py_ssize_t want,
                Py_ssize_t n_agents, object sc):
        """Place up to `want` static vehicles at roadside spots in `box` into the static slots
        of `sc`, clear of its first n_agents agents.

        Candidate draws u[0:5] (chunk, arc length, size); want * static_candidates_per_vehicle
        candidates at most. A candidate is accepted when it leaves `min_free_lane_width` of its
        lane free, its bounding circle keeps `static_gap` from every agent's and every accepted
        static vehicle's, and its box stays out of each agent's keep-clear zone: the agent's
        box grown by `static_gap` on every side and stretched forward by clear_ahead +
        speed * headway.

        Returns:
            (m static vehicles placed, then for the n_agents agents followed by the m static
            vehicles, as stored in `sc`: (n, 2) float64 centres [m], (n,) float64
            bounding-circle radii [m], (n,) bool standing still (parked agent or static)).
        """
        if want < 0 or n_agents < 0:
            raise ValueError(f"Placer.statics: want and n_agents must be >= 0, got {want}, {n_agents}")
        cdef RouteKernel r = roadside.r
        cdef bitgen_t* bg = _bitgen(rng)
        cdef Py_ssize_t k = roadside.count(box) if want > 0 else 0, n_ids, j, i, m = 0
        cdef double gap = self.static_gap
        cdef double u[5]
        cdef double o[3]
        cdef double L, W, rad, dx, dy, lim, ahead, c, s
        cdef bint ok
        cdef Pose p
        cdef const float* a_xy = <float*>_field(sc, "agent_xy", cnp.NPY_FLOAT32, 2 * n_agents)
        cdef const float* a_h = <float*>_field(sc, "agent_heading", cnp.NPY_FLOAT32, n_agents)
        cdef const float* a_v = <float*>_field(sc, "agent_speed", cnp.NPY_FLOAT32, n_agents)
        cdef const float* a_len = <float*>_field(sc, "agent_length", cnp.NPY_FLOAT32, n_agents)
        cdef const float* a_w = <float*>_field(sc, "agent_width", cnp.NPY_FLOAT32, n_agents)
        cdef const cnp.npy_bool* a_parked = <cnp.npy_bool*>_field(sc, "agent_parked", cnp.NPY_BOOL, n_agents)
        cdef cnp.npy_bool* s_valid = <cnp.npy_bool*>_field(sc, "static_valid", cnp.NPY_BOOL, want)
        cdef float* s_xy = <float*>_field(sc, "static_xy", cnp.NPY_FLOAT32, 2 * want)
        cdef float* s_h = <float*>_field(sc, "static_heading", cnp.NPY_FLOAT32, want)
        cdef float* s_len = <float*>_field(sc, "static_length", cnp.NPY_FLOAT32, want)
        cdef float* s_w = <float*>_field(sc, "static_width", cnp.NPY_FLOAT32, want)
        veh_xy_arr = np.empty((n_agents + want, 2))
        veh_r_arr = np.empty(n_agents + want)
        still_arr = np.empty(n_agents + want, dtype=bool)
        cdef f64* veh_xy = <f64*>cnp.PyArray_DATA(veh_xy_arr)
        cdef f64* veh_r = <f64*>cnp.PyArray_DATA(veh_r_arr)
        cdef cnp.npy_bool* still = <cnp.npy_bool*>cnp.PyArray_DATA(still_arr)
        # per agent: keep-clear zone centre x, y, cos, sin, half length, half width, its
        # circumradius, and the reach (from the agent's centre) of both tests
        cdef double* zone = <double*>_alloc(n_agents * 8 * sizeof(double))
        cdef double* acc = NULL
        cdef i64* ids = NULL
        cdef f64* cdf = NULL
        cdef double* z
        try:
            acc = <double*>_alloc(want * 3 * sizeof(double))
            ids = <i64*>_alloc(k * sizeof(i64))
            cdf = <f64*>_alloc(k * sizeof(f64))
            for i in range(n_agents):
                veh_xy[2 * i] = a_xy[2 * i]
                veh_xy[2 * i + 1] = a_xy[2 * i + 1]
                veh_r[i] = 0.5 * hypot(a_len[i], a_w[i])
                still[i] = a_parked[i]
                c = cos(a_h[i])
                s = sin(a_h[i])
                ahead = self.clear_ahead + a_v[i] * self.headway
                z = zone + 8 * i
                z[0] = a_xy[2 * i] + 0.5 * ahead * c
                z[1] = a_xy[2 * i + 1] + 0.5 * ahead * s
                z[2] = c
                z[3] = s
                z[4] = 0.5 * a_len[i] + gap + 0.5 * ahead
                z[5] = 0.5 * a_w[i] + gap
                z[6] = hypot(z[4], z[5])
                z[7] = veh_r[i] + gap if veh_r[i] + gap > 0.5 * ahead + z[6] else 0.5 * ahead + z[6]
            with rng.bit_generator.lock:
                n_ids = roadside.gather(box, ids, cdf) if k > 0 else 0
                for j in range(want * self.per_static if n_ids > 0 else 0):
                    _draw(bg, u, 5)
                    if not roadside.pose(ids, cdf, n_ids, box, u[0], u[1], &p):
                        continue
                    self.static_sizes.draw(&u[2], &L, &W)
                    # section 2.2: stationary vehicles must not block a lane completely
                    if not _roadside(p.x, p.y, r.hsin[p.piece], r.hcos[p.piece], W, r.lane_width[p.lane],
                                     roadside.edge[p.chunk], self.curb_gap, self.max_shoulder, self.min_free, o):
                        continue
                    rad = 0.5 * hypot(L, W)
                    ok = True
                    for i in range(n_agents):
                        z = zone + 8 * i
                        dx = o[0] - veh_xy[2 * i]
                        dy = o[1] - veh_xy[2 * i + 1]
                        lim = rad + z[7]
                        if dx * dx + dy * dy >= lim * lim:  # too far for either test
                            continue
                        lim = rad + veh_r[i] + gap
                        if dx * dx + dy * dy < lim * lim:
                            ok = False
                            break
                        dx = o[0] - z[0]
                        dy = o[1] - z[1]
                        lim = rad + z[6]
                        if dx * dx + dy * dy < lim * lim and _boxes_meet(
                            z[0], z[1], z[2], z[3], z[4], z[5], o[0], o[1], r.hcos[p.piece], r.hsin[p.piece],
                            0.5 * L, 0.5 * W,
                        ):
                            ok = False
                            break
                    if ok:
                        for i in range(m):
                            dx = o[0] - acc[3 * i]
                            dy = o[1] - acc[3 * i + 1]
                            lim = rad + acc[3 * i + 2] + gap
                            if dx * dx + dy * dy < lim * lim:
                                ok = False
                                break
                    if not ok:
                        continue
                    acc[3 * m] = o[0]
                    acc[3 * m + 1] = o[1]
                    acc[3 * m + 2] = rad
                    s_valid[m] = True
                    s_xy[2 * m] = <float>o[0]
                    s_xy[2 * m + 1] = <float>o[1]
                    s_h[m] = <float>r.heading[p.piece]
                    s_len[m] = <float>L
                    s_w[m] = <float>W
                    m += 1
                    if m >= want:
                        break
            for i in range(m):
                j = n_agents + i
                veh_xy[2 * j] = s_xy[2 * i]
                veh_xy[2 * j + 1] = s_xy[2 * i + 1]
                veh_r[j] = 0.5 * hypot(s_len[i], s_w[i])
                still[j] = True
        finally:
            free(zone)
            free(acc)
            free(ids)
            free(cdf)
        return m, veh_xy_arr[:n_agents + m], veh_r_arr[:n_agents + m], still_arr[:n_agents + m]
