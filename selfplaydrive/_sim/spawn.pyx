# cython: language_level=3
"""Spawner kernels (paper section 2.2): random route walks and greedy spaced selection.

They run once per world reset from `selfplaydrive.scenario` and `selfplaydrive.maps.routing`;
NumPy references with the same semantics are in `selfplaydrive/testing/spawn_reference.py`
and the tests compare them.
"""

import numpy as np

cimport numpy as cnp

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
    cdef i64 lo, hi, mid, ln
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
            lo = offsets[ln]
            hi = offsets[ln + 1] - 2
            # largest lo with gcum[lo] <= g, within [offsets[ln], offsets[ln + 1] - 2]
            while lo < hi:
                mid = (lo + hi + 1) >> 1
                if gcum[mid] <= g:
                    lo = mid
                else:
                    hi = mid - 1
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

    Returns:
        Number m of poses written to the first m rows of the outputs.
    """
    cdef Py_ssize_t ix0, ix1, iy0, iy1, i, c, k, q, n_ids = 0, m = 0, n = u.shape[0]
    cdef i64 lo, hi, md, ln, ch
    cdef double total = 0.0, g, target, f, x, y, s
    if n == 0:
        return 0
    ix0 = max(0, <Py_ssize_t>((box[0] - cell_origin[0]) // cell))
    iy0 = max(0, <Py_ssize_t>((box[1] - cell_origin[1]) // cell))
    ix1 = min(nx - 1, <Py_ssize_t>((box[2] - cell_origin[0]) // cell))
    iy1 = min(ny - 1, <Py_ssize_t>((box[3] - cell_origin[1]) // cell))
    if ix1 < ix0 or iy1 < iy0:
        return 0
    k = 0
    for i in range(ix0, ix1 + 1):
        k += cell_offsets[i * ny + iy1 + 1] - cell_offsets[i * ny + iy0]
    ids_arr = np.empty(k, dtype=np.int64)
    cdf_arr = np.empty(k, dtype=np.float64)
    cdef i64[::1] ids = ids_arr
    cdef f64[::1] cdf = cdf_arr
    with nogil:
        for i in range(ix0, ix1 + 1):
            for c in range(cell_offsets[i * ny + iy0], cell_offsets[i * ny + iy1 + 1]):
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
            lo = offsets[ln]
            hi = offsets[ln + 1] - 2
            while lo < hi:
                md = (lo + hi + 1) >> 1
                if gcum[md] <= g:
                    lo = md
                else:
                    hi = md - 1
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
    cdef Py_ssize_t a, k, p, n = lanes.shape[1], K = times.shape[1]
    cdef double total, t, t_before, s, x = 0.0, y = 0.0
    cdef int count
    cdef i64 ln
    with nogil:
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
