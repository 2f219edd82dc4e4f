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

from libc.stdint cimport int32_t, int64_t, uintptr_t
from selfplaydrive._sim.common cimport Sim, Params, Atlas, EGO_DIM, OBJ_DIM, ROAD_DIM
from selfplaydrive._sim.observe cimport encode_paper

import numpy as np

# obs/rules.py packs the same fields with RULES_HEAD_DTYPE (same order, no padding: 80 bytes),
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

cdef enum:
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


cdef bint occupied(const RulesHead* h, const void* args, int c, const float* px, const float* py,
                   const float* vx, const float* vy, const unsigned char* valid,
                   const unsigned char* here, int n) noexcept nogil:
    """Crosswalk c holds, now or `horizon` seconds ahead, one of the n pedestrian slots that
    are valid and present."""
    cdef const int32_t* cw_pts = <const int32_t*>at(args, h.cw_pts)
    cdef const float* poly = <const float*>at(args, h.pts) + 2 * cw_pts[c]
    cdef const float* box = <const float*>at(args, h.cw_box) + 4 * c
    cdef int k = cw_pts[c + 1] - cw_pts[c], j
    cdef double m2 = <double>h.margin * <double>h.margin, qx, qy, hz = h.horizon
    for j in range(n):
        if not (valid[j] and here[j]):
            continue
        if in_box(px[j], py[j], box) and inside_grown(px[j], py[j], poly, k, m2):
            return True
        qx = <double>px[j] + <double>vx[j] * hz
        qy = <double>py[j] + <double>vy[j] * hz
        if in_box(qx, qy, box) and inside_grown(qx, qy, poly, k, m2):
            return True
    return False


cdef int crosswalk_flags(const Sim* sim, const RulesHead* h, const void* args, int w, int c0,
                         int c1, float* flags) noexcept nogil:
    """flags[c - c0] = 1.0 for each occupied crosswalk c of [c0, c1) in world w, else 0;
    returns how many are occupied."""
    cdef int P = sim.P, k, busy = 0, here = 0
    cdef int64_t j = <int64_t>w * P
    for k in range(P):
        here += sim.ped_valid[j + k] and sim.ped_here[j + k]
    for k in range(c0, c1):
        flags[k - c0] = 0.0
        if here and occupied(h, args, k, &sim.ped_x[j], &sim.ped_y[j], &sim.ped_vx[j],
                             &sim.ped_vy[j], &sim.ped_valid[j], &sim.ped_here[j], P):
            flags[k - c0] = 1.0
            busy += 1
    return busy


cdef void mark_rows(float* o, const int32_t* idx, int n, const int32_t* code, int c0,
                    const float* flags, float stop_type, float busy_value) noexcept nogil:
    """Overwrite the rule features of road rows o[0..n) (row k shows atlas position idx[k])."""
    cdef int k, q
    for k in range(n):
        q = code[idx[k]]
        if q == CODE_STOP:
            o[k * ROAD_DIM + TYPE_COL] = stop_type
        elif q >= 0 and flags[q - c0] != 0.0:
            o[k * ROAD_DIM + STATE_COL] = busy_value


cdef void encode_rules(const Sim* sim, const Params* prm, const Atlas* atlas, const void* args,
                       int32_t w, float* obs, int32_t stride) noexcept nogil:
    """The paper encoder, then the rule features on the road rows of every active slot of world
    `w` (an `sd_encoder_fn`). NULL args (an encoder never bound to maps): the paper's rows."""
    cdef const RulesHead* h = <const RulesHead*>args
    cdef int a, i, m, c0, c1, busy
    cdef const int32_t* code
    cdef const int32_t* map_cw
    cdef float* flags
    encode_paper(sim, prm, atlas, NULL, w, obs, stride)
    if args == NULL or sim.max_road == 0:
        return
    m = sim.map_id[w]
    map_cw = <const int32_t*>at(args, h.map_cw)
    c0 = map_cw[m]
    c1 = map_cw[m + 1]
    # the paper encoder is done with the scratch: it holds one flag per crosswalk of the map now
    flags = (<Sim*>sim).cand_d + <int64_t>w * sim.cand_cap
    busy = crosswalk_flags(sim, h, args, w, c0, c1, flags)
    if busy == 0 and (<const int32_t*>at(args, h.map_stop))[m] == 0:
        return  # nothing to mark in this world (the paper's rows)
    code = <const int32_t*>at(args, h.seg_code)
    for a in range(sim.A):
        i = w * sim.A + a
        if sim.active[i]:
            mark_rows(obs + <int64_t>a * stride + EGO_DIM + sim.max_obj * OBJ_DIM,
                      &sim.road_idx[<int64_t>i * sim.max_road], sim.road_n[i], code, c0, flags,
                      h.stop_type, h.occupied)


def occupied_flags(const unsigned char[::1] args, int m, const float[::1] x, const float[::1] y,
                   const float[::1] vx, const float[::1] vy):
    """The kernel's occupancy of every crosswalk of map m for the given present pedestrians
    (tests compare it with obs/rule_features.py): (crosswalks of m,) bool."""
    if args.shape[0] < <Py_ssize_t>sizeof(RulesHead):
        raise ValueError(f"args: expected at least {sizeof(RulesHead)} bytes, got {args.shape[0]}")
    cdef const RulesHead* h = <const RulesHead*>&args[0]
    if not 0 <= m < h.num_maps:
        raise ValueError(f"m: expected a map index in [0, {h.num_maps}), got {m}")
    cdef int n = x.shape[0], c
    if not (y.shape[0] == n and vx.shape[0] == n and vy.shape[0] == n):
        raise ValueError("x, y, vx, vy: expected arrays of one length")
    cdef const int32_t* map_cw = <const int32_t*>at(&args[0], h.map_cw)
    out = np.zeros(map_cw[m + 1] - map_cw[m], dtype=bool)
    if n == 0:
        return out
    ones = np.ones(n, dtype=np.uint8)
    cdef const unsigned char[::1] on = ones
    for c in range(map_cw[m], map_cw[m + 1]):
        out[c - map_cw[m]] = occupied(h, &args[0], c, &x[0], &y[0], &vx[0], &vy[0], &on[0],
                                      &on[0], n)
    return out
