# cython: language_level=3
"""Traffic-rule features as an observation encoder (issue #15 item 1; docs/observation.md
"Traffic-rule features"): the paper encoder (section 2.5, same layout, so models and checkpoints
work unchanged), then, on each agent's road rows,

1. a stop line of a STOP sign gets the type value `stop_type` (YIELD lines keep the paper's
   0.5: section 2.1 treats every line as a yield line);
2. a crosswalk segment whose crosswalk is occupied (a present pedestrian's centre, or its centre
   `horizon` seconds ahead, inside the polygon grown by `margin`) gets `occupied` in the state
   column, which is 0 on every segment but a traffic-light line.

The map data (which atlas positions are STOP lines and which crosswalk a segment outlines, the
crosswalk polygons) is packed once per env by obs/rules.py `RulesEncoder.bind`; constants and
the NumPy form of the rule: selfplaydrive/obs/rule_features.py; reference of the whole encoder:
selfplaydrive/testing/rules_reference.py.
"""

from libc.math cimport floor
from libc.stdint cimport int32_t, int64_t, uintptr_t
from libc.string cimport memset
from selfplaydrive._sim.common cimport Sim, Params, Atlas, EGO_DIM, OBJ_DIM, ROAD_DIM
from selfplaydrive._sim.observe cimport (encode_paper, body_floats, body_table, write_ego,
                                         write_objects, write_road)

import numpy as np

# obs/rules.py packs the same fields with RULES_HEAD_DTYPE (same order, no padding: 136 bytes),
# followed by the arrays at the byte offsets it gives
ctypedef struct RulesHead:
    int32_t num_positions   # Ns, atlas positions covered by seg_code
    int32_t num_maps        # M
    int32_t num_crosswalks  # C
    int32_t num_points      # outline points of all crosswalks
    float margin            # [m] growth of the crosswalk polygons
    float horizon           # [s] look-ahead of "about to enter"
    float stop_type         # type value of a STOP-kind line's row
    float occupied          # state value of an occupied crosswalk's row
    int64_t seg_code        # byte offset of (Ns,) int32: CODE_STOP, crosswalk index or CODE_NONE
    int64_t map_cw          # (M + 1,) int32 crosswalks of map m: [map_cw[m], map_cw[m + 1])
    int64_t map_stop        # (M,) int32 STOP-kind segments of map m
    int64_t cw_pts          # (C + 1,) int32 outline of crosswalk c: points [cw_pts[c], cw_pts[c + 1])
    int64_t pts             # (points, 2) float32 [m]
    int64_t cw_box          # (C, 4) float32 [m] grown bounding box
    int64_t grid_origin     # (M, 3) float32 [m] crosswalk grid of map m: corner x, y, cell edge
    int64_t grid_dims       # (M, 3) int32 nx, ny, first entry of the map's cells in cell_start
    int64_t cell_start      # CSR over the cells (nx * ny + 1 entries per map) into cell_items
    int64_t cell_items      # int32 crosswalks whose grown box meets the cell
    int64_t stop_grid       # (M, 3) float32 [m] STOP-line grid of map m: corner x, y, cell edge
    int64_t stop_dims       # (M, 3) int32 nx, ny, first entry of the map's table in stop_sat
    int64_t stop_sat        # int32 summed-area tables of STOP-line midpoints per cell

cdef enum:
    HALF_BITS = 0x3F000000  # 0.5f, the paper's stop-line type
    CODE_STOP = -2
    TYPE_COL = 6    # columns of a road row (obs/layout.py ROAD_FEATURES)
    STATE_COL = 7


def head_size():
    """sizeof(RulesHead), checked against obs/rules.py RULES_HEAD_DTYPE."""
    return sizeof(RulesHead)


def encoder_address():
    """Address of `encode_rules` (an `sd_encoder_fn`)."""
    return <uintptr_t>encode_rules


cdef inline const char* at(const void* args, int64_t offset) noexcept nogil:
    return <const char*>args + offset


cdef bint inside_grown(double px, double py, const float* poly, int k, double m2) noexcept nogil:
    """Point inside the polygon of k points or within sqrt(m2) of its outline (the arithmetic
    of obs/rule_features.py `inside_grown_polygon`)."""
    cdef int e
    cdef bint inside = False
    cdef double ax, ay, bx, by, ex, ey, ll, t, dx, dy
    for e in range(k):
        ax = poly[2 * e]
        ay = poly[2 * e + 1]
        bx = poly[2 * ((e + 1) % k)]
        by = poly[2 * ((e + 1) % k) + 1]
        if (ay > py) != (by > py):
            if px < (bx - ax) * (py - ay) / (by - ay) + ax:
                inside = not inside
        ex = bx - ax
        ey = by - ay
        ll = ex * ex + ey * ey
        t = 0.0 if ll <= 0.0 else ((px - ax) * ex + (py - ay) * ey) / ll
        t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
        dx = px - (ax + t * ex)
        dy = py - (ay + t * ey)
        if dx * dx + dy * dy <= m2:
            return True
    return inside


cdef inline bint in_box(double x, double y, const float* box) noexcept nogil:
    return box[0] <= x <= box[2] and box[1] <= y <= box[3]


cdef int mark_point(const RulesHead* h, const void* args, int m, double x, double y, int c0,
                    float* flags) noexcept nogil:
    """Flag (flags[c - c0] = 1) every crosswalk c of map m whose grown polygon holds the point;
    only the crosswalks listed in the point's grid cell are tested. Returns how many it newly
    flagged."""
    cdef const float* g = <const float*>at(args, h.grid_origin) + 3 * m
    cdef const int32_t* d = <const int32_t*>at(args, h.grid_dims) + 3 * m
    cdef const int32_t* start = <const int32_t*>at(args, h.cell_start)
    cdef const int32_t* items = <const int32_t*>at(args, h.cell_items)
    cdef const int32_t* cw_pts = <const int32_t*>at(args, h.cw_pts)
    cdef const float* pts = <const float*>at(args, h.pts)
    cdef const float* boxes = <const float*>at(args, h.cw_box)
    cdef double fx = floor((x - <double>g[0]) / <double>g[2])
    cdef double fy = floor((y - <double>g[1]) / <double>g[2])
    cdef double m2 = <double>h.margin * <double>h.margin
    cdef int ix, iy, t, c, n = 0
    if not (fx >= 0.0 and fx < d[0] and fy >= 0.0 and fy < d[1]):
        return 0  # outside the grid: no crosswalk's box reaches here
    ix = <int>fx
    iy = <int>fy
    t = d[2] + ix * d[1] + iy
    for t in range(start[t], start[t + 1]):
        c = items[t]
        if flags[c - c0] == 0.0 and in_box(x, y, boxes + 4 * c) and inside_grown(
                x, y, pts + 2 * cw_pts[c], cw_pts[c + 1] - cw_pts[c], m2):
            flags[c - c0] = 1.0
            n += 1
    return n


cdef int crosswalk_flags(const Sim* sim, const RulesHead* h, const void* args, int w, int m,
                         int c0, int c1, float* flags) noexcept nogil:
    """flags[c - c0] = 1.0 for each occupied crosswalk c of [c0, c1) (map m's) in world w, else
    0: each present pedestrian's centre and its centre `horizon` seconds ahead are tested
    against the crosswalks of their grid cells. Returns how many are occupied."""
    cdef int k, busy = 0
    cdef int64_t j
    cdef double hz = h.horizon
    memset(flags, 0, (c1 - c0) * sizeof(float))
    for k in range(sim.P):
        j = <int64_t>w * sim.P + k
        if sim.ped_valid[j] and sim.ped_here[j]:
            busy += mark_point(h, args, m, sim.ped_x[j], sim.ped_y[j], c0, flags)
            busy += mark_point(h, args, m, <double>sim.ped_x[j] + <double>sim.ped_vx[j] * hz,
                               <double>sim.ped_y[j] + <double>sim.ped_vy[j] * hz, c0, flags)
    return busy


cdef int busy_list(const float* flags, int c0, int c1, int32_t* ids) noexcept nogil:
    """The occupied crosswalks (global indices) into ids; returns their number."""
    cdef int c, n = 0
    for c in range(c0, c1):
        if flags[c - c0] != 0.0:
            ids[n] = c
            n += 1
    return n


cdef bint sees_busy(const Sim* sim, int i, const float* boxes, const int32_t* ids,
                    int n) noexcept nogil:
    """Whether agent i's road gather can hold a segment of one of the n occupied crosswalks
    `ids`: the gathered midpoints lie within road_r of (road_x, road_y) (_sim/road.pyx), a
    crosswalk's outline within its grown box."""
    cdef int k
    cdef float r = sim.road_r[i] + 0.05, x = sim.road_x[i], y = sim.road_y[i], dx, dy
    cdef const float* b
    if sim.road_r[i] < 0.0:
        return True  # no gather recorded: look at the rows
    for k in range(n):
        b = boxes + 4 * ids[k]
        dx = b[0] - x if x < b[0] else (x - b[2] if x > b[2] else 0.0)
        dy = b[1] - y if y < b[1] else (y - b[3] if y > b[3] else 0.0)
        if dx * dx + dy * dy <= r * r:
            return True
    return False


cdef inline int clampi(double v, int hi) noexcept nogil:
    """floor(v) clamped to [0, hi]."""
    if v <= 0.0:
        return 0
    if v >= hi:
        return hi
    return <int>floor(v)


cdef bint sees_stop(const Sim* sim, const RulesHead* h, const void* args, int m,
                    int i) noexcept nogil:
    """Whether a STOP-line segment midpoint of map m lies in the square of cells around agent
    i's gather disc (road_r around (road_x, road_y), _sim/road.pyx): four reads of the map's
    summed-area table. The gathered midpoints lie in that disc, so False means none is a STOP
    line."""
    cdef const float* g = <const float*>at(args, h.stop_grid) + 3 * m
    cdef const int32_t* d = <const int32_t*>at(args, h.stop_dims) + 3 * m
    cdef const int32_t* sat = <const int32_t*>at(args, h.stop_sat) + d[2]
    cdef double r = <double>sim.road_r[i] + 0.05, x = sim.road_x[i], y = sim.road_y[i]
    cdef double c = g[2]
    cdef int x0, x1, y0, y1, ny1 = d[1] + 1
    if sim.road_r[i] < 0.0:
        return True  # no gather recorded: look at the rows
    # cells [x0, x1) x [y0, y1) cover the square (clamped to the grid)
    x0 = clampi(floor((x - r - g[0]) / c), d[0])
    x1 = clampi(floor((x + r - g[0]) / c) + 1.0, d[0])
    y0 = clampi(floor((y - r - g[1]) / c), d[1])
    y1 = clampi(floor((y + r - g[1]) / c) + 1.0, d[1])
    if x1 <= x0 or y1 <= y0:
        return False
    return sat[x1 * ny1 + y1] - sat[x0 * ny1 + y1] - sat[x1 * ny1 + y0] + sat[x0 * ny1 + y0] > 0


cdef inline float max4(float a, float b, float c, float d) noexcept nogil:
    a = a if a > b else b
    c = c if c > d else d
    return a if a > c else c


cdef inline void mark_row(float* r, int32_t pos, const int32_t* code, int c0, const float* flags,
                          bint stops, bint busy, float stop_type, float busy_value) noexcept nogil:
    """Rule features of one road row `r` showing atlas position `pos` (see mark_rows); the
    code is read only for a stop line or crosswalk row (a random access into a large array)."""
    cdef float t = r[TYPE_COL]
    cdef int32_t q
    if t == 0.5 and stops:
        if code[pos] == CODE_STOP:
            r[TYPE_COL] = stop_type
    elif t == 1.0 and busy:
        q = code[pos]
        if q >= 0 and flags[q - c0] != 0.0:
            r[STATE_COL] = busy_value


cdef void mark_rows(float* o, const int32_t* idx, int n, const int32_t* code, int c0,
                    const float* flags, bint stops, bint busy, float stop_type,
                    float busy_value) noexcept nogil:
    """Overwrite the rule features of road rows o[0..n) (row k shows atlas position idx[k]).
    Only rows the paper typed stop line (0.5) or crosswalk (1) can change (`stops`: the map has
    STOP lines; `busy`: a crosswalk of the world is occupied): groups of four rows whose types
    are all below 0.5 (lane centres and edges, most rows) are passed over with one test."""
    cdef int k = 0, j
    cdef float* r
    cdef const int32_t* b
    cdef bint hit
    while k + 4 <= n:
        r = o + k * ROAD_DIM + TYPE_COL
        if busy:
            hit = max4(r[0], r[ROAD_DIM], r[2 * ROAD_DIM], r[3 * ROAD_DIM]) >= 0.5
        else:  # only stop lines can change: crosswalk and light rows do not stop the scan
            # (compared as bit patterns: one integer compare per row, no unordered case)
            b = <const int32_t*>r
            hit = ((b[0] == HALF_BITS) | (b[ROAD_DIM] == HALF_BITS) | (b[2 * ROAD_DIM] == HALF_BITS)
                   | (b[3 * ROAD_DIM] == HALF_BITS))
        if hit:
            for j in range(k, k + 4):
                mark_row(o + j * ROAD_DIM, idx[j], code, c0, flags, stops, busy, stop_type,
                         busy_value)
        k += 4
    for j in range(k, n):
        mark_row(o + j * ROAD_DIM, idx[j], code, c0, flags, stops, busy, stop_type, busy_value)


cdef void encode_rules(const Sim* sim, const Params* prm, const Atlas* atlas, const void* args,
                       int32_t w, float* obs, int32_t stride) noexcept nogil:
    """The paper encoder, then the rule features on the road rows of every active slot of world
    `w` (an `sd_encoder_fn`). NULL args (an encoder never bound to maps): the paper's rows.

    The crosswalk flags go to the end of the world's scratch when the paper's body table leaves
    room there (the default cand_cap of 8192 floats does): then each agent's road rows are
    marked right after they are written, while in cache. Otherwise (a small cand_cap) the paper
    encoder runs first and the flags reuse its scratch; both give the same rows."""
    cdef const RulesHead* h = <const RulesHead*>args
    cdef int m, c0, c1, busy
    cdef bint stops
    cdef float* scratch = (<Sim*>sim).cand_d + <int64_t>w * sim.cand_cap
    cdef float* flags
    cdef int32_t* ids
    if args == NULL or sim.max_road == 0:
        encode_paper(sim, prm, atlas, NULL, w, obs, stride)
        return
    m = sim.map_id[w]
    c0 = (<const int32_t*>at(args, h.map_cw))[m]
    c1 = (<const int32_t*>at(args, h.map_cw))[m + 1]
    stops = (<const int32_t*>at(args, h.map_stop))[m] > 0
    if sim.cand_cap - (c1 - c0) >= body_floats(sim.A, sim.S, sim.P):
        # flags and the list of occupied crosswalks at the ends of the float and int scratch,
        # past the paper's body table (and its 2 NB + 3 ints of candidates, fewer than that)
        flags = scratch + sim.cand_cap - (c1 - c0)
        ids = (<Sim*>sim).cand + <int64_t>w * sim.cand_cap + sim.cand_cap - (c1 - c0)
        busy = crosswalk_flags(sim, h, args, w, m, c0, c1, flags)
        if busy == 0 and not stops:
            encode_paper(sim, prm, atlas, NULL, w, obs, stride)  # nothing to mark in this world
        else:
            busy = busy_list(flags, c0, c1, ids)
            observe_marked(<Sim*>sim, prm, atlas, h, args, w, obs, stride, flags, c0, stops, ids,
                           busy)
        return
    encode_paper(sim, prm, atlas, NULL, w, obs, stride)
    flags = scratch  # the paper encoder is done with it
    ids = (<Sim*>sim).cand + <int64_t>w * sim.cand_cap
    busy = crosswalk_flags(sim, h, args, w, m, c0, c1, flags)
    if busy > 0 or stops:
        busy = busy_list(flags, c0, c1, ids)
        mark_world(sim, h, args, w, obs, stride, flags, c0, stops, ids, busy)


cdef void observe_marked(Sim* sim, const Params* prm, const Atlas* atlas, const RulesHead* h,
                         const void* args, int w, float* obs, int64_t stride, const float* flags,
                         int c0, bint stops, const int32_t* ids, int nbusy) noexcept nogil:
    """observe.pyx `observe_world` (the paper's rows, same calls in the same order), marking
    each agent's road rows right after they are written; an agent's rows are looked at only
    when the map has STOP lines or an occupied crosswalk is within its gather."""
    cdef int a, i, nb, own = 0
    cdef bint busy, stop
    cdef float* row
    cdef const float* boxes = <const float*>at(args, h.cw_box)
    cdef float* table = sim.cand_d + <int64_t>w * sim.cand_cap
    cdef int32_t* owner = sim.cand + <int64_t>w * sim.cand_cap
    cdef const int32_t* code = <const int32_t*>at(args, h.seg_code)
    nb = body_table(sim, prm, w, table, owner)
    for a in range(sim.A):
        i = w * sim.A + a
        if sim.active[i]:
            row = obs + a * stride
            write_ego(sim, prm, i, row)
            write_objects(sim, prm, w, i, own, table, nb, row + EGO_DIM)
            row += EGO_DIM + sim.max_obj * OBJ_DIM
            write_road(sim, atlas, prm, w, i, row)
            busy = nbusy > 0 and sees_busy(sim, i, boxes, ids, nbusy)
            stop = stops and sees_stop(sim, h, args, sim.map_id[w], i)
            if stop or busy:
                mark_rows(row, &sim.road_idx[<int64_t>i * sim.max_road], sim.road_n[i], code,
                          c0, flags, stop, busy, h.stop_type, h.occupied)
        own += sim.active[i] or sim.obstacle[i]


cdef void mark_world(const Sim* sim, const RulesHead* h, const void* args, int w, float* obs,
                     int64_t stride, const float* flags, int c0, bint stops, const int32_t* ids,
                     int nbusy) noexcept nogil:
    """Mark the road rows of every active slot of world `w`, after the paper encoder (the
    agents as in observe_marked)."""
    cdef int a, i
    cdef bint busy, stop
    cdef const int32_t* code = <const int32_t*>at(args, h.seg_code)
    cdef const float* boxes = <const float*>at(args, h.cw_box)
    for a in range(sim.A):
        i = w * sim.A + a
        if not sim.active[i]:
            continue
        busy = nbusy > 0 and sees_busy(sim, i, boxes, ids, nbusy)
        stop = stops and sees_stop(sim, h, args, sim.map_id[w], i)
        if stop or busy:
            mark_rows(obs + a * stride + EGO_DIM + sim.max_obj * OBJ_DIM,
                      &sim.road_idx[<int64_t>i * sim.max_road], sim.road_n[i], code, c0, flags,
                      stop, busy, h.stop_type, h.occupied)


def occupied_flags(const unsigned char[::1] args, int m, const float[::1] x, const float[::1] y,
                   const float[::1] vx, const float[::1] vy):
    """The kernel's occupancy of every crosswalk of map m for the given present pedestrians, by
    the same grid and tests as a world's step (tests compare it with obs/rule_features.py):
    (crosswalks of m,) bool."""
    if args.shape[0] < <Py_ssize_t>sizeof(RulesHead):
        raise ValueError(f"args: expected at least {sizeof(RulesHead)} bytes, got {args.shape[0]}")
    cdef const RulesHead* h = <const RulesHead*>&args[0]
    if not 0 <= m < h.num_maps:
        raise ValueError(f"m: expected a map index in [0, {h.num_maps}), got {m}")
    cdef int n = x.shape[0], j
    if not (y.shape[0] == n and vx.shape[0] == n and vy.shape[0] == n):
        raise ValueError("x, y, vx, vy: expected arrays of one length")
    cdef const int32_t* map_cw = <const int32_t*>at(&args[0], h.map_cw)
    flags = np.zeros(map_cw[m + 1] - map_cw[m] + 1, dtype=np.float32)
    cdef float[::1] f = flags
    cdef double hz = h.horizon
    for j in range(n):
        mark_point(h, &args[0], m, x[j], y[j], map_cw[m], &f[0])
        mark_point(h, &args[0], m, <double>x[j] + <double>vx[j] * hz,
                   <double>y[j] + <double>vy[j] * hz, map_cw[m], &f[0])
    return flags[: map_cw[m + 1] - map_cw[m]] != 0.0
