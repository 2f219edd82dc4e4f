# cython: language_level=3
"""Agent and static-vehicle placement (paper section 2.2): `Placer` places a world's agents and
static vehicles on poses that `ChunkKernel` (_sim/chunks.pyx) draws on the spawn and roadside
lane chunks, one candidate at a time from the world's generator (its bit generator's
`next_double`: the values `rng.random` would give), so a reset computes only the candidates it
tries. NumPy references
with the same semantics and draws are in `selfplaydrive/testing/spawn_reference.py`; the tests
compare them bit for bit.
"""

import numpy as np

cimport numpy as cnp
from libc.math cimport cos, fabs, hypot, sin
from libc.stdlib cimport free
from numpy.random cimport bitgen_t
from selfplaydrive._sim.spawn_common cimport (
    f64, i64, _alloc, _bitgen, _draw, _field, _size, _wrap_angle,
)
from selfplaydrive._sim.chunks cimport ChunkKernel, Pose
from selfplaydrive._sim.waypoints cimport RouteKernel

cnp.import_array()


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
        cdef bitgen_t* bg = _bitgen(rng)
        cdef Py_ssize_t k_r = roadside.count(box) if n_parked > 0 else 0, k_s = spawn.count(box)
        cdef Py_ssize_t k = k_r if k_r > k_s else k_s, got = 0, parked
        cdef double* rows = <double*>_alloc(want * NCOL * sizeof(double))
        cdef Py_ssize_t* order = NULL
        cdef i64* ids = NULL
        cdef f64* cdf = NULL
        cdef double* buf = NULL
        try:
            order = <Py_ssize_t*>_alloc(want * sizeof(Py_ssize_t))
            ids = <i64*>_alloc(k * sizeof(i64))
            cdf = <f64*>_alloc(k * sizeof(f64))
            buf = <double*>_alloc(want * self.first * 8 * sizeof(double))
            with rng.bit_generator.lock:
                if k_r > 0:
                    got = self._parked(roadside, bg, box, n_parked, ids, cdf, rows)
                parked = got
                if k_s > 0 and want > parked:
                    got = self._aligned(spawn, bg, box, want, got, ids, cdf, buf, rows)
                _shuffle(bg, order, got)
            lane_arr, s_arr = self._write_agents(rows, order, got, sc, want)
        finally:
            free(rows)
            free(order)
            free(ids)
            free(cdf)
            free(buf)
        return got, parked, lane_arr, s_arr

    cdef Py_ssize_t _parked(self, ChunkKernel roadside, bitgen_t* bg, const f64[::1] box, Py_ssize_t n_parked,
                            i64* ids, f64* cdf, double* rows) noexcept:
        """Up to n_parked parked agents at roadside spots into rows[0:]; returns their number."""
        cdef Py_ssize_t got = 0, j, n_ids = roadside.gather(box, ids, cdf)
        cdef RouteKernel r = roadside.r
        cdef double u[5]
        cdef double o[3]
        cdef double L, W, lw
        cdef bint fits
        cdef Pose p
        cdef double* row
        for j in range(n_parked * self.per_agent if n_ids > 0 else 0):
            # a parked agent may block its lane (fits is not required, unlike a static vehicle)
            if not _roadside_candidate(roadside, r, bg, box, ids, cdf, n_ids, self.sizes, self.curb_gap,
                                       self.max_shoulder, 0.0, u, &p, &L, &W, o, &fits):
                continue
            if not _spaced(rows, got, o[0], o[1], self.min_dist):
                continue
            lw = r.lane_width[p.lane]
            row = rows + got * NCOL
            row[COL_LANE] = <double>p.lane
            row[COL_S] = p.s
            row[COL_X] = o[0]
            row[COL_Y] = o[1]
            row[COL_HEADING] = r.heading[p.piece]
            row[COL_SPEED] = 0.0
            row[COL_LENGTH] = L
            row[COL_WIDTH] = W
            row[COL_PARKED] = 1.0
            row[COL_ON_LANE] = 1.0 if o[2] <= lw / 2 else 0.0
            got += 1
            if got >= n_parked:
                break
        return got

    cdef Py_ssize_t _aligned(self, ChunkKernel spawn, bitgen_t* bg, const f64[::1] box, Py_ssize_t want,
                             Py_ssize_t got, i64* ids, f64* cdf, double* buf, double* rows) noexcept:
        """Aligned agents on the spawn chunks after the `got` parked ones, until `want` in all
        (the first need * first_round_candidates draws taken as one block into buf); returns
        the number of agents in rows."""
        cdef RouteKernel r = spawn.r
        cdef Py_ssize_t need = want - got, block = 0, j, n_ids = spawn.gather(box, ids, cdf)
        cdef double lim = self.min_dist, near = self.min_dist - self.lateral_noise - 1e-6
        cdef double u[8]
        cdef double* uu
        cdef double L, W
        cdef Pose p
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
            # the lateral shift moves the centre at most lateral_noise: a pose that close to an
            # agent is rejected for sure, before its size and noise
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
        return got

    cdef tuple _write_agents(self, const double* rows, const Py_ssize_t* order, Py_ssize_t got, object sc,
                             Py_ssize_t want):
        """Rows in slot order into the agent slots of `sc`; returns the route starts (lane, s)."""
        cdef cnp.npy_bool* valid = <cnp.npy_bool*>_field(sc, "agent_valid", cnp.NPY_BOOL, want)
        cdef float* xy = <float*>_field(sc, "agent_xy", cnp.NPY_FLOAT32, 2 * want)
        cdef float* heading = <float*>_field(sc, "agent_heading", cnp.NPY_FLOAT32, want)
        cdef float* speed = <float*>_field(sc, "agent_speed", cnp.NPY_FLOAT32, want)
        cdef float* length = <float*>_field(sc, "agent_length", cnp.NPY_FLOAT32, want)
        cdef float* width = <float*>_field(sc, "agent_width", cnp.NPY_FLOAT32, want)
        cdef cnp.npy_bool* parked_out = <cnp.npy_bool*>_field(sc, "agent_parked", cnp.NPY_BOOL, want)
        cdef cnp.int32_t* lane_out = <cnp.int32_t*>_field(sc, "agent_lane", cnp.NPY_INT32, want)
        cdef Py_ssize_t i
        cdef const double* row
        lane_arr = np.empty(got, dtype=np.int64)
        s_arr = np.empty(got)
        for i in range(got):
            row = rows + order[i] * NCOL
            valid[i] = True
            xy[2 * i] = <float>row[COL_X]
            xy[2 * i + 1] = <float>row[COL_Y]
            heading[i] = <float>row[COL_HEADING]
            speed[i] = <float>row[COL_SPEED]
            length[i] = <float>row[COL_LENGTH]
            width[i] = <float>row[COL_WIDTH]
            parked_out[i] = row[COL_PARKED] != 0.0
            lane_out[i] = <cnp.int32_t>row[COL_LANE] if row[COL_ON_LANE] != 0.0 else -1
            (<i64*>cnp.PyArray_DATA(lane_arr))[i] = <i64>row[COL_LANE]
            (<f64*>cnp.PyArray_DATA(s_arr))[i] = row[COL_S]
        return lane_arr, s_arr

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
        cdef bitgen_t* bg = _bitgen(rng)
        cdef Py_ssize_t k = roadside.count(box) if want > 0 else 0, i, j, m = 0
        cdef float* s_xy = <float*>_field(sc, "static_xy", cnp.NPY_FLOAT32, 2 * want)
        cdef float* s_len = <float*>_field(sc, "static_length", cnp.NPY_FLOAT32, want)
        cdef float* s_w = <float*>_field(sc, "static_width", cnp.NPY_FLOAT32, want)
        veh_xy_arr = np.empty((n_agents + want, 2))
        veh_r_arr = np.empty(n_agents + want)
        still_arr = np.empty(n_agents + want, dtype=bool)
        cdef f64* veh_xy = <f64*>cnp.PyArray_DATA(veh_xy_arr)
        cdef f64* veh_r = <f64*>cnp.PyArray_DATA(veh_r_arr)
        cdef cnp.npy_bool* still = <cnp.npy_bool*>cnp.PyArray_DATA(still_arr)
        cdef double* zone = <double*>_alloc(n_agents * 8 * sizeof(double))
        cdef i64* ids = NULL
        cdef f64* cdf = NULL
        try:
            ids = <i64*>_alloc(k * sizeof(i64))
            cdf = <f64*>_alloc(k * sizeof(f64))
            self._agent_zones(sc, n_agents, veh_xy, veh_r, still, zone)
            if k > 0:
                with rng.bit_generator.lock:
                    m = self._place_statics(roadside, bg, box, want, n_agents, veh_xy, veh_r, zone, ids, cdf, sc)
            for i in range(m):
                j = n_agents + i
                veh_xy[2 * j] = s_xy[2 * i]
                veh_xy[2 * j + 1] = s_xy[2 * i + 1]
                veh_r[j] = 0.5 * hypot(s_len[i], s_w[i])
                still[j] = True
        finally:
            free(zone)
            free(ids)
            free(cdf)
        return m, veh_xy_arr[:n_agents + m], veh_r_arr[:n_agents + m], still_arr[:n_agents + m]

    cdef int _agent_zones(self, object sc, Py_ssize_t n_agents, f64* veh_xy, f64* veh_r, cnp.npy_bool* still,
                          double* zone) except -1:
        """Per agent of `sc`: its centre, bounding-circle radius and whether it stands still, and
        its keep-clear zone: centre x, y, cos, sin, half length, half width, the zone's
        circumradius, and the reach (from the agent's centre) of both static-vehicle tests."""
        cdef const float* a_xy = <float*>_field(sc, "agent_xy", cnp.NPY_FLOAT32, 2 * n_agents)
        cdef const float* a_h = <float*>_field(sc, "agent_heading", cnp.NPY_FLOAT32, n_agents)
        cdef const float* a_v = <float*>_field(sc, "agent_speed", cnp.NPY_FLOAT32, n_agents)
        cdef const float* a_len = <float*>_field(sc, "agent_length", cnp.NPY_FLOAT32, n_agents)
        cdef const float* a_w = <float*>_field(sc, "agent_width", cnp.NPY_FLOAT32, n_agents)
        cdef const cnp.npy_bool* a_parked = <cnp.npy_bool*>_field(sc, "agent_parked", cnp.NPY_BOOL, n_agents)
        cdef Py_ssize_t i
        cdef double c, s, ahead, gap = self.static_gap
        cdef double* z
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
        return 0

    cdef Py_ssize_t _place_statics(self, ChunkKernel roadside, bitgen_t* bg, const f64[::1] box, Py_ssize_t want,
                                   Py_ssize_t n_agents, const f64* veh_xy, const f64* veh_r, const double* zone,
                                   i64* ids, f64* cdf, object sc) except -1:
        """The candidate loop of `statics`: accepted vehicles into the static slots of `sc`;
        returns their number."""
        cdef RouteKernel r = roadside.r
        cdef cnp.npy_bool* s_valid = <cnp.npy_bool*>_field(sc, "static_valid", cnp.NPY_BOOL, want)
        cdef float* s_xy = <float*>_field(sc, "static_xy", cnp.NPY_FLOAT32, 2 * want)
        cdef float* s_h = <float*>_field(sc, "static_heading", cnp.NPY_FLOAT32, want)
        cdef float* s_len = <float*>_field(sc, "static_length", cnp.NPY_FLOAT32, want)
        cdef float* s_w = <float*>_field(sc, "static_width", cnp.NPY_FLOAT32, want)
        cdef Py_ssize_t j, m = 0, n_ids = roadside.gather(box, ids, cdf)
        cdef double u[5]
        cdef double o[3]
        cdef double L, W, rad
        cdef bint fits
        cdef Pose p
        cdef double* acc = <double*>_alloc(want * 3 * sizeof(double))
        try:
            for j in range(want * self.per_static if n_ids > 0 else 0):
                if not _roadside_candidate(roadside, r, bg, box, ids, cdf, n_ids, self.static_sizes,
                                           self.curb_gap, self.max_shoulder, self.min_free, u, &p, &L, &W, o,
                                           &fits):
                    continue
                if not fits:  # section 2.2: stationary vehicles must not block a lane completely
                    continue
                rad = 0.5 * hypot(L, W)
                if not _clear_of_agents(zone, veh_xy, veh_r, n_agents, o, rad, self.static_gap,
                                        r.hcos[p.piece], r.hsin[p.piece], L, W):
                    continue
                if not _clear_of_statics(acc, m, o, rad, self.static_gap):
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
        finally:
            free(acc)
        return m


cdef inline bint _roadside_candidate(ChunkKernel roadside, RouteKernel r, bitgen_t* bg, const f64[::1] box,
                                     const i64* ids, const f64* cdf, Py_ssize_t n_ids, SizeTable sizes,
                                     double curb_gap, double max_shoulder, double min_free, double* u, Pose* p,
                                     double* L, double* W, double* o, bint* fits) noexcept:
    """One roadside candidate (parked agents and static vehicles) from the next draws u[0:5]
    (chunk, arc length, size): its pose on the n_ids gathered chunks (False when outside `box`:
    the draws are spent all the same), its size and the centre beside the lane (`_roadside`:
    o = x, y, offset; fits: it leaves `min_free` m of its lane free). r: the chunks' route
    tables (`roadside.r`, passed so the candidate loop holds no reference of its own)."""
    _draw(bg, u, 5)
    if not roadside.pose(ids, cdf, n_ids, box, u[0], u[1], p):
        return False
    sizes.draw(&u[2], L, W)
    fits[0] = _roadside(p.x, p.y, r.hsin[p.piece], r.hcos[p.piece], W[0], r.lane_width[p.lane],
                        roadside.edge[p.chunk], curb_gap, max_shoulder, min_free, o)
    return True


cdef inline bint _clear_of_agents(const double* zone, const f64* veh_xy, const f64* veh_r, Py_ssize_t n_agents,
                                  const double* o, double rad, double gap, double c, double s, double L,
                                  double W) noexcept nogil:
    """Whether a static vehicle at o (bounding radius rad, heading (c, s), size L x W) keeps
    `gap` from every agent's bounding circle and stays out of every agent's keep-clear zone
    (`Placer._agent_zones`)."""
    cdef Py_ssize_t i
    cdef double dx, dy, lim
    cdef const double* z
    for i in range(n_agents):
        z = zone + 8 * i
        dx = o[0] - veh_xy[2 * i]
        dy = o[1] - veh_xy[2 * i + 1]
        lim = rad + z[7]
        if dx * dx + dy * dy >= lim * lim:  # too far for either test
            continue
        lim = rad + veh_r[i] + gap
        if dx * dx + dy * dy < lim * lim:
            return False
        dx = o[0] - z[0]
        dy = o[1] - z[1]
        lim = rad + z[6]
        if dx * dx + dy * dy < lim * lim and _boxes_meet(z[0], z[1], z[2], z[3], z[4], z[5], o[0], o[1], c, s,
                                                         0.5 * L, 0.5 * W):
            return False
    return True


cdef inline bint _clear_of_statics(const double* acc, Py_ssize_t m, const double* o, double rad,
                                   double gap) noexcept nogil:
    """Whether a static vehicle at o (bounding radius rad) keeps `gap` from the m accepted
    ones (acc: x, y, radius each)."""
    cdef Py_ssize_t i
    cdef double dx, dy, lim
    for i in range(m):
        dx = o[0] - acc[3 * i]
        dy = o[1] - acc[3 * i + 1]
        lim = rad + acc[3 * i + 2] + gap
        if dx * dx + dy * dy < lim * lim:
            return False
    return True


cdef inline void _shuffle(bitgen_t* bg, Py_ssize_t* order, Py_ssize_t n) noexcept nogil:
    """order = a permutation of 0..n-1: Fisher-Yates from the last slot down, one draw each."""
    cdef Py_ssize_t i, j, tmp
    for i in range(n):
        order[i] = i
    for i in range(n - 1, 0, -1):
        j = <Py_ssize_t>(bg.next_double(bg.state) * (i + 1))
        if j > i:
            j = i
        tmp = order[i]
        order[i] = order[j]
        order[j] = tmp
