# cython: language_level=3
"""Lane-graph kernels of one map (paper section 2.2): random legal route walks, points at an
arc length on a lane, and waypoints at given times along routes.

Map-level: `selfplaydrive.maps.routing` calls them, and the spawner's `RouteKernel`
(_sim/waypoints.pyx) through lanes.pxd. The walks draw from a counter-based hash, not from a
generator; the NumPy twins are in `selfplaydrive/testing/spawn_reference.py`.
"""

import numpy as np

cimport numpy as cnp

cnp.import_array()


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


cdef void walk_one(
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
            walk_one(succ_off, succ_idx, left, right, length, speed, start_lane[a], s, horizon[a],
                      key, a, p_change, min_change, changes, lanes[a], s0[a], s1[a], change[a], t_end[a],
                      &dead[a])


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
        waypoints_into(lanes, s_start, s_end, t_end, times, speed, gcum, px, py, base, length,
                         offsets, out_xy, out_count)


cdef void waypoints_into(
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
