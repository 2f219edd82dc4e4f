# cython: language_level=3
"""Rule-complete reward terms (issue #15; the failure modes of paper section 5.1): entering a
junction area on red by any path, crossing a STOP line without stopping, entering a crosswalk
a pedestrian is on or about to step on, driving against the lane direction, and turning
through a junction lane the lane entered from does not lead to (paper 5.3).

Each is an `sd_reward_term_fn` component (selfplaydrive_abi.h) whose args are the packed
tables of selfplaydrive/rewards/rule_tables.py: a header (state offset, layout version, number
of maps), the term's parameters, one offset per map, then per map a uniform grid whose cells
list the records (zones, line segments, polygons, lane segments) whose bounding box, grown by
the reach of one step, meets the cell. A query reads the one cell of the agent's current
centre. The NumPy references (selfplaydrive/testing/rule_terms.py) loop over every record of
the map instead; tests/rewards/test_rules.py compares both on random rollouts.
"""

from libc.math cimport sqrtf, fabsf

cdef double HALF_PI = 1.5707963267948966
from libc.stdint cimport int32_t, int64_t, uintptr_t
from selfplaydrive._sim.common cimport Sim, Params, Atlas, LIGHT_RED
from selfplaydrive._sim.geometry cimport clip1 as clip  # one Liang-Barsky half-plane

cdef enum:
    H_MAPS = 2        # args[2]: number of maps (args[0]: state offset, args[1]: layout version)
    H_PARAMS = 3      # the term's parameters start here; then the per-map body offsets
    B_ORIGIN = 0      # body: grid origin x, y [m], 1 / cell edge [1/m], nx, ny, record width,
    B_INV_CELL = 2    # then the offsets (from the body start) of the cell CSR, the items
    B_NX = 3          # and the records, then a number of the map the term defines
    B_NY = 4
    B_WIDTH = 5
    B_CELLS = 6
    B_ITEMS = 7
    B_RECS = 8
    B_SCALAR = 9


def rule_term_addresses():
    """{name: address} of the rule terms (rewards/rules.py registers them)."""
    return {
        "red_intersection": <uintptr_t>term_red_intersection,
        "stop_sign": <uintptr_t>term_stop_sign,
        "crosswalk_yield": <uintptr_t>term_crosswalk_yield,
        "wrong_way": <uintptr_t>term_wrong_way,
        "turn_lane": <uintptr_t>term_turn_lane,
    }


ctypedef struct Cell:
    const float* recs     # the map's first record
    const float* items    # record indices listed in the cell
    int n                 # how many
    int width             # floats per record
    float scalar          # the map's number (rule_tables.py)


cdef inline bint map_cell(const float* args, int nparams, int m, float x, float y,
                          Cell* c) noexcept nogil:
    """The grid cell of map `m` holding (x, y); False (and c.n = 0) outside the grid or in an
    empty cell (c.scalar is set whenever m is a valid map)."""
    cdef const float* body
    cdef float fx, fy
    cdef int nx, ny, k
    cdef int64_t lo, hi
    c.n = 0
    if m < 0 or m >= <int>args[H_MAPS]:
        return False
    body = args + <int64_t>args[H_PARAMS + nparams + m]
    c.scalar = body[B_SCALAR]
    fx = (x - body[B_ORIGIN]) * body[B_INV_CELL]
    fy = (y - body[B_ORIGIN + 1]) * body[B_INV_CELL]
    nx = <int>body[B_NX]
    ny = <int>body[B_NY]
    if not (fx >= 0.0 and fy >= 0.0 and fx < nx and fy < ny):  # NaN fails too
        return False
    k = <int>fx * ny + <int>fy
    lo = <int64_t>body[<int64_t>body[B_CELLS] + k]
    hi = <int64_t>body[<int64_t>body[B_CELLS] + k + 1]
    c.items = body + <int64_t>body[B_ITEMS] + lo
    c.n = <int>(hi - lo)
    c.recs = body + <int64_t>body[B_RECS]
    c.width = <int>body[B_WIDTH]
    return c.n > 0


cdef inline const float* record(const Cell* c, int j) noexcept nogil:
    return c.recs + <int64_t>c.items[j] * c.width


# ---- red_intersection ------------------------------------------------------------------------
cdef inline bint in_zone(const float* z, float x, float y, float L, float R, float D) noexcept nogil:
    """(x, y) inside zone z = (cx, cy, ux, uy, group): 0 <= along <= D, -R <= left <= L."""
    cdef float dx = x - z[0], dy = y - z[1]
    cdef float al = dx * z[2] + dy * z[3], lt = dy * z[2] - dx * z[3]
    return 0.0 <= al <= D and -R <= lt <= L


cdef inline bint enters_zone(const float* z, float px, float py, float qx, float qy, float L,
                             float R, float D) noexcept nogil:
    """The move p -> q meets zone z while p lies outside it."""
    cdef float dx = px - z[0], dy = py - z[1]
    cdef float ap = dx * z[2] + dy * z[3], bp = dy * z[2] - dx * z[3]
    cdef float ex = qx - z[0], ey = qy - z[1]
    cdef float da = (ex * z[2] + ey * z[3]) - ap, db = (ey * z[2] - ex * z[3]) - bp
    cdef float t0 = 0.0, t1 = 1.0
    if 0.0 <= ap <= D and -R <= bp <= L:
        return False
    return (clip(-da, ap, &t0, &t1) and clip(da, D - ap, &t0, &t1)
            and clip(-db, bp + R, &t0, &t1) and clip(db, L - bp, &t0, &t1))


cdef void term_red_intersection(const Sim* sim, const Params* prm, const Atlas* atlas,
                                const float* args, int32_t w, float* out,
                                int32_t stride) noexcept nogil:
    """-1 on the step the centre enters the controlled area of a red light (maps/
    rule_geometry.py) heading within the parameter angle of its approach, having been in no
    area of that signal group before the step; else 0. Params: GATE_LEFT, GATE_RIGHT,
    GATE_DEPTH [m], cos of the largest heading deviation."""
    cdef int a, i, j, k, g, A = sim.A, G = sim.G
    cdef float L = args[H_PARAMS], R = args[H_PARAMS + 1], D = args[H_PARAMS + 2]
    cdef float cmax = args[H_PARAMS + 3], px, py, qx, qy
    cdef const float* z
    cdef const float* o
    cdef bint hit, before
    cdef Cell c
    for a in range(A):
        i = w * A + a
        if not sim.active[i]:
            continue
        out[<int64_t>a * stride] = 0.0
        if not sim.lights_on[w] or not map_cell(args, 4, sim.map_id[w], sim.x[i], sim.y[i], &c):
            continue
        px, py, qx, qy = sim.px[i], sim.py[i], sim.x[i], sim.y[i]
        hit = False
        for j in range(c.n):
            z = record(&c, j)
            g = <int>z[4]
            if g < 0 or g >= G or sim.light_state[w * G + g] != LIGHT_RED:
                continue
            if sim.hcos[i] * z[2] + sim.hsin[i] * z[3] < cmax:
                continue
            if not enters_zone(z, px, py, qx, qy, L, R, D):
                continue
            before = False  # already inside another area of the same group: no new entry
            for k in range(c.n):
                o = record(&c, k)
                if <int>o[4] == g and in_zone(o, px, py, L, R, D):
                    before = True
                    break
            if not before:
                hit = True
                break
        if hit:
            out[<int64_t>a * stride] = -1.0


# ---- stop_sign -------------------------------------------------------------------------------
cdef inline int crossing(const float* s, float px, float py, float qx, float qy) noexcept nogil:
    """+1 if the move p -> q goes from the approach side of line segment s = (ax, ay, ex, ey,
    nx, ny) (start, direction b - a, unit normal pointing along the lane) to the far side (on
    the line counts as far) through the segment, -1 if it goes through it the other way, else 0.
    stop_sign takes +1; turn_lane's gates use the same layout."""
    cdef float sp = (px - s[0]) * s[4] + (py - s[1]) * s[5]
    cdef float sq = (qx - s[0]) * s[4] + (qy - s[1]) * s[5]
    cdef float f, cx, cy, t
    if (sp < 0.0) == (sq < 0.0):
        return 0
    f = sp / (sp - sq)
    cx = px + f * (qx - px)
    cy = py + f * (qy - py)
    t = ((cx - s[0]) * s[2] + (cy - s[1]) * s[3]) / (s[2] * s[2] + s[3] * s[3])
    if not (0.0 <= t <= 1.0):
        return 0
    return 1 if sp < 0.0 else -1


cdef void term_stop_sign(const Sim* sim, const Params* prm, const Atlas* atlas, const float* args,
                         int32_t w, float* out, int32_t stride) noexcept nogil:
    """-1 on the step the centre crosses a STOP line in its lane's direction unless the agent
    is stopped (speed <= v_stop) or stopped at most `distance` + length / 2 m of driving ago;
    else 0. One state column: 0 = no stop on record, else 1 + metres driven since the last
    stop. Params: v_stop [m/s], distance [m]."""
    cdef int a, i, j, A = sim.A, off = <int>args[0]
    cdef float vs = args[H_PARAMS], dist = args[H_PARAMS + 1], s, dx, dy
    cdef float* st
    cdef bint crossed, ok
    cdef Cell c
    for a in range(A):
        i = w * A + a
        if not sim.active[i]:
            continue
        st = &sim.term_state[<int64_t>i * sim.term_state_dim + off]
        s = st[0]
        crossed = False
        if map_cell(args, 2, sim.map_id[w], sim.x[i], sim.y[i], &c):
            for j in range(c.n):
                if crossing(record(&c, j), sim.px[i], sim.py[i], sim.x[i], sim.y[i]) > 0:
                    crossed = True
                    break
        ok = sim.speed[i] <= vs or (s > 0.0 and s - 1.0 <= dist + 0.5 * sim.length[i])
        out[<int64_t>a * stride] = -1.0 if crossed and not ok else 0.0
        if sim.speed[i] <= vs:
            st[0] = 1.0
        elif s > 0.0:
            dx = sim.x[i] - sim.px[i]
            dy = sim.y[i] - sim.py[i]
            st[0] = s + sqrtf(dx * dx + dy * dy)


# ---- crosswalk_yield -------------------------------------------------------------------------
cdef inline bint in_polygon(const float* poly, float x, float y) noexcept nogil:
    """Even-odd test of (x, y) in poly = (nv, xmin, ymin, xmax, ymax, x0, y0, ...)."""
    cdef int k, n = <int>poly[0]
    cdef const float* v = poly + 5
    cdef float x0, y0, x1, y1
    cdef bint inside = False
    if not (poly[1] <= x <= poly[3] and poly[2] <= y <= poly[4]):
        return False
    for k in range(n):
        x0, y0 = v[2 * k], v[2 * k + 1]
        x1, y1 = v[2 * ((k + 1) % n)], v[2 * ((k + 1) % n) + 1]
        if (y0 > y) != (y1 > y) and x < x0 + (y - y0) * (x1 - x0) / (y1 - y0):
            inside = not inside
    return inside


cdef inline float orient(float ax, float ay, float bx, float by, float cx, float cy) noexcept nogil:
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)


cdef inline bint crosses_polygon(const float* poly, float px, float py, float qx, float qy) noexcept nogil:
    """The segment p -> q properly crosses an edge of the polygon."""
    cdef int k, n = <int>poly[0]
    cdef const float* v = poly + 5
    cdef float x0, y0, x1, y1
    for k in range(n):
        x0, y0 = v[2 * k], v[2 * k + 1]
        x1, y1 = v[2 * ((k + 1) % n)], v[2 * ((k + 1) % n) + 1]
        if ((orient(px, py, qx, qy, x0, y0) > 0.0) != (orient(px, py, qx, qy, x1, y1) > 0.0)
                and (orient(x0, y0, x1, y1, px, py) > 0.0) != (orient(x0, y0, x1, y1, qx, qy) > 0.0)):
            return True
    return False


cdef inline float edge_dist2(const float* poly, float x, float y) noexcept nogil:
    """Squared distance [m^2] of (x, y) to the polygon's outline."""
    cdef int k, n = <int>poly[0]
    cdef const float* v = poly + 5
    cdef float x0, y0, ex, ey, t, dx, dy, d2, best = 3.0e38
    for k in range(n):
        x0, y0 = v[2 * k], v[2 * k + 1]
        ex = v[2 * ((k + 1) % n)] - x0
        ey = v[2 * ((k + 1) % n) + 1] - y0
        t = ((x - x0) * ex + (y - y0) * ey) / (ex * ex + ey * ey)
        t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
        dx = x - (x0 + t * ex)
        dy = y - (y0 + t * ey)
        d2 = dx * dx + dy * dy
        if d2 < best:
            best = d2
    return best


cdef inline bint near_polygon(const float* poly, float x, float y, float margin) noexcept nogil:
    """(x, y) inside the polygon grown by `margin` [m]."""
    if not (poly[1] - margin <= x <= poly[3] + margin and poly[2] - margin <= y <= poly[4] + margin):
        return False
    return in_polygon(poly, x, y) or edge_dist2(poly, x, y) <= margin * margin


cdef inline bint pedestrian_on(const Sim* sim, int w, const float* poly, float ahead,
                               float margin) noexcept nogil:
    """A present pedestrian of world w is on the grown crosswalk now or `ahead` s from now."""
    cdef int k, j
    for k in range(sim.P):
        j = w * sim.P + k
        if not (sim.ped_valid[j] and sim.ped_here[j]):
            continue
        if near_polygon(poly, sim.ped_x[j], sim.ped_y[j], margin):
            return True
        if near_polygon(poly, sim.ped_x[j] + sim.ped_vx[j] * ahead,
                        sim.ped_y[j] + sim.ped_vy[j] * ahead, margin):
            return True
    return False


cdef void term_crosswalk_yield(const Sim* sim, const Params* prm, const Atlas* atlas,
                               const float* args, int32_t w, float* out,
                               int32_t stride) noexcept nogil:
    """-1 on the step the centre enters a crosswalk polygon (outside before the step, inside
    after it or crossing its outline) while a pedestrian is on it or will be within t_ahead s
    at its current velocity (polygon grown by margin); else 0. Params: t_ahead [s], margin [m]."""
    cdef int a, i, j, A = sim.A
    cdef float ahead = args[H_PARAMS], margin = args[H_PARAMS + 1], px, py, qx, qy
    cdef const float* poly
    cdef Cell c
    for a in range(A):
        i = w * A + a
        if not sim.active[i]:
            continue
        out[<int64_t>a * stride] = 0.0
        if not map_cell(args, 2, sim.map_id[w], sim.x[i], sim.y[i], &c):
            continue
        px, py, qx, qy = sim.px[i], sim.py[i], sim.x[i], sim.y[i]
        for j in range(c.n):
            poly = record(&c, j)
            # a move whose box misses the polygon's box cannot enter it
            if (max(px, qx) < poly[1] or min(px, qx) > poly[3] or max(py, qy) < poly[2]
                    or min(py, qy) > poly[4]):
                continue
            if in_polygon(poly, px, py):
                continue
            if not (in_polygon(poly, qx, qy) or crosses_polygon(poly, px, py, qx, qy)):
                continue
            if pedestrian_on(sim, w, poly, ahead, margin):
                out[<int64_t>a * stride] = -1.0
                break


# ---- wrong_way -------------------------------------------------------------------------------
cdef void term_wrong_way(const Sim* sim, const Params* prm, const Atlas* atlas, const float* args,
                         int32_t w, float* out, int32_t stride) noexcept nogil:
    """-dt (i.e. -1 per second) per step while the agent drives faster than v_min with its
    centre within half a lane width of a centerline segment heading more than 90 degrees from
    its own heading and of none heading within 90 degrees of it; else 0. Params: v_min [m/s].
    Shortcut: a car whose lane association (events stage) puts it within the map's narrowest
    half lane width of a centerline heading within 90 degrees of it is on a lane going its
    way (most cars, most steps), and the segment scan is skipped."""
    cdef int a, i, j, A = sim.A
    cdef float vmin = args[H_PARAMS], x, y, dx, dy, t
    cdef const float* s
    cdef bint against, along
    cdef Cell c
    for a in range(A):
        i = w * A + a
        if not sim.active[i]:
            continue
        out[<int64_t>a * stride] = 0.0
        if sim.speed[i] <= vmin:
            continue
        x, y = sim.x[i], sim.y[i]
        if not map_cell(args, 1, sim.map_id[w], x, y, &c):
            continue
        if (sim.lane_valid[i] and fabsf(sim.lane_alpha[i]) < HALF_PI
                and fabsf(sim.lane_s[i]) <= c.scalar):
            continue
        against = False
        along = False
        for j in range(c.n):
            s = record(&c, j)  # (ax, ay, ux, uy, length, half width)
            dx = x - s[0]
            dy = y - s[1]
            t = dx * s[2] + dy * s[3]
            if t < 0.0 or t > s[4] or fabsf(dx * s[3] - dy * s[2]) > s[5]:
                continue
            if sim.hcos[i] * s[2] + sim.hsin[i] * s[3] >= 0.0:
                along = True
                break
            against = True
        if against and not along:
            out[<int64_t>a * stride] = -prm.dt


# ---- turn_lane -------------------------------------------------------------------------------
cdef enum:
    T_KIND = 6        # turn_records: (ax, ay, ex, ey, ux, uy, kind, lane, n, p_0 ..)
    T_LANE = 7
    T_NPRED = 8
    T_PREDS = 9


cdef inline bint leads_from(const float* g, int entry) noexcept nogil:
    """Check gate g's junction lane is a successor of lane `entry`."""
    cdef int k
    for k in range(<int>g[T_NPRED]):
        if <int>g[T_PREDS + k] == entry:
            return True
    return False


cdef void term_turn_lane(const Sim* sim, const Params* prm, const Atlas* atlas, const float* args,
                         int32_t w, float* out, int32_t stride) noexcept nogil:
    """-1 on the step the centre crosses the mid gate of one or more junction lanes, heading
    within the parameter angle of one, none of which the entry lane on record leads to; else
    0. One state column: 0 = no entry on record, else 1 + the lane whose end gate the centre
    crossed last (forward; the lowest lane if a move crosses several). Entry gates are read
    before check gates (a move crosses a junction's start before a lane's middle); crossing
    check gates decides and clears the record. Params: cos of the largest heading deviation,
    entry_back [m] (where the entry gates stand: the tables' business, not read here)."""
    cdef int a, i, j, e, s, A = sim.A, off = <int>args[0]
    cdef float cmax = args[H_PARAMS], px, py, qx, qy
    cdef const float* g
    cdef float* st
    cdef bint crossed, legal
    cdef Cell c
    for a in range(A):
        i = w * A + a
        if not sim.active[i]:
            continue
        out[<int64_t>a * stride] = 0.0
        if not map_cell(args, 2, sim.map_id[w], sim.x[i], sim.y[i], &c):
            continue
        st = &sim.term_state[<int64_t>i * sim.term_state_dim + off]
        px, py, qx, qy = sim.px[i], sim.py[i], sim.x[i], sim.y[i]
        e = -1
        for j in range(c.n):
            g = record(&c, j)
            if g[T_KIND] == 0.0 and (e < 0 or <int>g[T_LANE] < e) and crossing(g, px, py, qx, qy) > 0:
                e = <int>g[T_LANE]
        s = e + 1 if e >= 0 else <int>st[0]
        if s == 0:  # nothing on record: a check gate would decide nothing
            continue
        crossed = False
        legal = False
        for j in range(c.n):
            g = record(&c, j)
            if g[T_KIND] == 0.0 or sim.hcos[i] * g[4] + sim.hsin[i] * g[5] < cmax:
                continue
            if crossing(g, px, py, qx, qy) != 0:
                crossed = True
                if leads_from(g, s - 1):
                    legal = True
                    break
        if crossed:
            if not legal:
                out[<int64_t>a * stride] = -1.0
            s = 0
        st[0] = <float>s
