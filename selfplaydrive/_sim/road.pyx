# cython: language_level=3
"""The road gather of one step (paper sections 2.3, 2.5): per agent, the segments within
reach of its box give road-edge contact, red-light crossing and lane association; the nearest
`max_road` segments within obs_radius are selected for the road observation (docs/world.md,
"Road gather"). Waypoint and comfort events are set here too.
"""

from libc.math cimport sqrt, floor, atan2f, fabs
from libc.stdint cimport int32_t, int64_t
from libc.string cimport memcpy
from selfplaydrive._sim.common cimport (Sim, Params, Atlas, SEG_LANE, SEG_EDGE, SEG_LIGHT,
                                        LIGHT_RED, EV_OFFROAD, EV_RED, EV_WAYPOINT, EV_COMFORT,
                                        C_RADIUS)
from selfplaydrive._sim.geometry cimport seg_box, segs_cross, box_radius, select_nearest_binned

cdef extern from "scan.h" nogil:
    int spd_scan_init(int want)
    int32_t spd_fbits(float f)
    void spd_scan_split_c(const float* mx, const float* my, int lo, int cnt, float x, float y,
                          int32_t ilo, int32_t ihi, int32_t* inner, int* ni, int32_t* shell,
                          float* shell_d, int* ns)
    void spd_scan_columns(const float* mx, const float* my, const int32_t* cols, int ncols,
                          float x, float y, int32_t ilo, int32_t ihi, int32_t iev,
                          int32_t* inner, int* ni, int32_t* shell, float* shell_d, int* ns,
                          int32_t* ev, float* ev_d, int* ne)

# grid columns collected before one call of the scan (scan.h spd_scan_columns)
DEF COLS = 48


def _set_simd(int level):
    """Set this module's SIMD level (selfplaydrive._sim.simd_level); returns the level used."""
    return spd_scan_init(level)


from selfplaydrive._sim import requested_simd
_set_simd(requested_simd())

# [m] slack on the distance bounds of the road gather: covers float32 rounding of distances
DEF RPAD = 0.01
# [m] slack on the per-segment reach of the road-event pre-tests (float32 rounding)
DEF EPAD = 0.01
# candidates sorted into per-type lists at a time by road_events (stack scratch: 3 lists)
DEF EV_CHUNK = 128


cdef void road_world(Sim* sim, const Atlas* atlas, const Params* prm, int w) noexcept nogil:
    """One road gather per active agent of world `w`: road-edge contact, red-light crossing,
    lane association, waypoint and comfort events, and the nearest `max_road` segments kept in
    `road_idx` for the observation (section 2.5)."""
    cdef int a, i
    for a in range(sim.A):
        i = w * sim.A + a
        if sim.active[i]:
            road_agent(sim, atlas, prm, w, i)
            waypoint_comfort(sim, prm, i)


cdef void waypoint_comfort(Sim* sim, const Params* prm, int i) noexcept nogil:
    cdef int k = sim.wp_idx[i]
    cdef float dx, dy, r
    if k < sim.num_wp[i]:
        dx = sim.waypoints[(i * sim.K + k) * 2] - sim.x[i]
        dy = sim.waypoints[(i * sim.K + k) * 2 + 1] - sim.y[i]
        r = sim.coeffs[i * 8 + C_RADIUS]
        if dx * dx + dy * dy < r * r:
            sim.events[i] |= EV_WAYPOINT
            sim.wp_idx[i] = k + 1
    if fabs(sim.a_long[i]) > prm.comfort_limit or fabs(sim.a_lat[i]) > prm.comfort_limit:
        sim.events[i] |= EV_COMFORT


cdef void road_agent(Sim* sim, const Atlas* atlas, const Params* prm, int w, int i) noexcept nogil:
    """Road events from the segments near agent i, then the `max_road` nearest segments within
    obs_radius into `road_idx` (atlas positions until the observation stage converts them)."""
    cdef int m = sim.map_id[w], n, cap = sim.cand_cap, maxr = sim.max_road, keep
    cdef float x = sim.x[i], y = sim.y[i], R = prm.obs_radius
    cdef float hl = 0.5 * sim.length[i], hw = 0.5 * sim.width[i], half_seg = 0.5 * atlas.max_seg_len[m]
    cdef float dpx = x - sim.px[i], dpy = y - sim.py[i], moved, near, lane_far, ev, prev, lo, hi
    cdef float dmax2 = 0.0, box_r, step
    cdef int32_t* cand = sim.cand + <int64_t>w * cap
    cdef float* cd = sim.cand_d + <int64_t>w * cap
    step = sqrt(dpx * dpx + dpy * dpy)
    # a segment can touch the box only when its midpoint is within box radius + half the
    # longest segment + this step's motion (swept red-light crossing)
    box_r = box_radius(hl, hw)
    near = box_r + half_seg + step
    lane_far = prm.lane_radius + half_seg
    ev = max(near, lane_far)
    prev = sim.road_r[i]
    keep = -1
    lo = hi = 0.0
    if prev >= 0.0:
        # d_k (distance of the k-th nearest midpoint) is 1-Lipschitz in the position: after
        # moving by `moved` it lies in [prev - moved, prev + moved]; everything nearer than the
        # lower bound is kept unsorted, only the thin shell between the bounds is selected
        dpx = x - sim.road_x[i]
        dpy = y - sim.road_y[i]
        moved = sqrt(dpx * dpx + dpy * dpy)
        hi = min(prev + moved + RPAD, R)
        lo = prev - moved - RPAD
        keep = gather_bounded(sim, atlas, prm, w, i, lo, hi, ev, near * near, lane_far * lane_far,
                              box_r, step, &dmax2)
    if keep < 0:
        # first gather of an episode, or a scratch overflow: events disc, then the bounded
        # split (when a bound exists) or the ring search
        n = scan_disc(atlas, m, x, y, ev, cand, cd, cap)
        road_events(sim, atlas, prm, w, i, cand, cd, n, near * near, lane_far * lane_far, box_r, step)
        if prev >= 0.0:
            keep = nearest_in_bounds(sim, atlas, w, i, lo, hi, cand, cd, &dmax2)
        if keep < 0:
            keep = nearest_by_rings(sim, atlas, prm, w, i, cand, cd, &dmax2)
    sim.road_n[i] = keep
    sim.road_r[i] = sqrt(dmax2) if keep >= maxr else R
    sim.road_x[i] = x
    sim.road_y[i] = y


cdef inline int ifloor(float v) noexcept nogil:
    """floor(v) as an int for |v| < 2^31 (no libm call)."""
    cdef int k = <int>v
    return k - (v < k)


cdef int gather_bounded(Sim* sim, const Atlas* atlas, const Params* prm, int w, int i, float lo,
                        float hi, float ev, float near2, float lane_far2, float box_r, float step,
                        float* dmax2) noexcept nogil:
    """Road events and the nearest `max_road` in one pass over the grid columns meeting the
    disc of radius max(hi, ev): every candidate's squared distance is split into inner
    (< lo: kept), shell (selected) and, in the cells meeting the events disc of radius `ev`,
    the events list. Same results as scan_disc + road_events + nearest_in_bounds. Returns the
    count kept, or -1 (nothing written) when a scratch part would overflow or the inner part
    does not fit (never with a valid bound); the caller then takes the separate passes."""
    cdef int m = sim.map_id[w], nx = atlas.grid_nx[m], ny = atlas.grid_ny[m], ix, y0, y1
    cdef int ni = 0, ns = 0, ne = 0, cap = sim.cand_cap, q = sim.cand_cap // 4
    cdef int maxr = sim.max_road, a, b, nc = 0, total = 0
    cdef int32_t cols[3 * COLS]
    cdef int32_t* col
    cdef const int32_t* offs = atlas.cell_offsets + atlas.cell_base[m]
    cdef float x = sim.x[i], y = sim.y[i], cell = atlas.grid_cell[m], inv, gx, gy, gs, ge, dx, h
    cdef float S = max(hi, ev)
    cdef int32_t ilo = spd_fbits(lo * lo) if lo > 0.0 else -1, ihi = spd_fbits(hi * hi)
    cdef int32_t iev = spd_fbits(ev * ev)
    cdef int32_t* cand = sim.cand + <int64_t>w * cap
    cdef float* cd = sim.cand_d + <int64_t>w * cap
    cdef int32_t* inner = cand            # [0, q): kept for sure
    cdef int32_t* evl = cand + q          # [q, 2q): within the events radius
    cdef float* evl_d = cd + q            # their squared distances
    cdef int32_t* shell = cand + 2 * q    # [2q, cap): to be selected, with distances
    cdef float* shell_d = cd + 2 * q
    cdef int scap = cap - 2 * q
    cdef int32_t* out = &sim.road_idx[<int64_t>i * maxr]
    if ilo > ihi:
        ilo = ihi
    inv = 1.0 / cell
    gx = clamp_cells((x - atlas.grid_origin[2 * m]) * inv)
    gy = clamp_cells((y - atlas.grid_origin[2 * m + 1]) * inv)
    gs = clamp_reach(S * inv)
    ge = ev * inv
    for ix in range(max(ifloor(gx - gs), 0), min(ifloor(gx + gs), nx - 1) + 1):
        dx = max(max(ix - gx, gx - (ix + 1)), 0.0)
        h = gs * gs - dx * dx
        if h < 0.0:
            continue
        h = sqrt(h)
        y0 = max(ifloor(gy - h), 0)
        y1 = min(ifloor(gy + h), ny - 1)
        if y0 > y1:
            continue
        a = offs[ix * ny + y0]
        b = offs[ix * ny + y1 + 1]
        total += b - a
        if total + 7 > q or total + 7 > scap:
            return -1  # the scratch parts could overflow
        col = &cols[3 * nc]
        col[0] = a
        col[1] = b
        # the column meets the events disc: list its candidates within ev too (a candidate
        # within ev lies in a cell that meets the disc, so these are scan_disc's candidates)
        col[2] = ge * ge - dx * dx >= 0.0
        nc += 1
        if nc == COLS:
            spd_scan_columns(atlas.seg_mx, atlas.seg_my, cols, nc, x, y, ilo, ihi, iev, inner,
                             &ni, shell, shell_d, &ns, evl, evl_d, &ne)
            nc = 0
    spd_scan_columns(atlas.seg_mx, atlas.seg_my, cols, nc, x, y, ilo, ihi, iev, inner, &ni,
                     shell, shell_d, &ns, evl, evl_d, &ne)
    if ni >= maxr:
        return -1
    road_events(sim, atlas, prm, w, i, evl, evl_d, ne, near2, lane_far2, box_r, step)
    memcpy(out, inner, ni * sizeof(int32_t))
    return append_shell(atlas, out, ni, shell, shell_d, ns, maxr, max(lo * lo, 0.0), hi * hi, dmax2)


cdef int nearest_in_bounds(Sim* sim, const Atlas* atlas, int w, int i, float lo, float hi,
                           int32_t* cand, float* cd, float* dmax2) noexcept nogil:
    """The nearest `max_road` when the max_road-th distance is known to lie in [lo, hi] [m]:
    one pass over the cells meeting the disc of radius hi splits the candidates into inner
    (< lo: kept) and shell (selected). Returns the count kept, or -1 when the inner part
    does not fit (never with a valid bound; the caller then falls back to the ring search)."""
    cdef int m = sim.map_id[w], nx = atlas.grid_nx[m], ny = atlas.grid_ny[m], ix, lo_y, hi_y
    cdef int ni = 0, ns = 0, half = sim.cand_cap // 2, maxr = sim.max_road, cnt, a
    cdef const int32_t* offs = atlas.cell_offsets + atlas.cell_base[m]
    cdef float x = sim.x[i], y = sim.y[i], cell = atlas.grid_cell[m], inv, gx, gy, gr, dx, h
    cdef int32_t ilo = spd_fbits(lo * lo) if lo > 0.0 else -1, ihi = spd_fbits(hi * hi)
    cdef int32_t* out = &sim.road_idx[<int64_t>i * maxr]
    if ilo > ihi:
        ilo = ihi
    inv = 1.0 / cell
    gx = clamp_cells((x - atlas.grid_origin[2 * m]) * inv)
    gy = clamp_cells((y - atlas.grid_origin[2 * m + 1]) * inv)
    gr = clamp_reach(hi * inv)
    for ix in range(max(<int>floor(gx - gr), 0), min(<int>floor(gx + gr), nx - 1) + 1):
        dx = max(max(ix - gx, gx - (ix + 1)), 0.0)
        h = gr * gr - dx * dx
        if h < 0.0:
            continue
        h = sqrt(h)
        lo_y = max(<int>floor(gy - h), 0)
        hi_y = min(<int>floor(gy + h), ny - 1)
        if lo_y > hi_y:
            continue
        a = offs[ix * ny + lo_y]
        cnt = min(offs[ix * ny + hi_y + 1] - a, min(half - ni, half - ns))  # cand_cap semantics
        # plain C: writes no lane past the capacity computed above
        spd_scan_split_c(atlas.seg_mx, atlas.seg_my, a, cnt, x, y, ilo, ihi, cand, &ni,
                         cand + half, cd + half, &ns)
    if ni >= maxr:
        return -1
    memcpy(out, cand, ni * sizeof(int32_t))
    return append_shell(atlas, out, ni, cand + half, cd + half, ns, maxr, max(lo * lo, 0.0),
                        hi * hi, dmax2)


cdef int nearest_by_rings(Sim* sim, const Atlas* atlas, const Params* prm, int w, int i,
                          int32_t* cand, float* cd, float* dmax2) noexcept nogil:
    """The nearest `max_road` without a previous distance (first gather of an episode): scan
    ring by ring of grid cells until the safe radius holds max_road candidates."""
    cdef int m = sim.map_id[w], nx = atlas.grid_nx[m], ny = atlas.grid_ny[m], cx, cy, j = 0
    cdef int n = 0, cap = sim.cand_cap, maxr = sim.max_road
    cdef const int32_t* offs = atlas.cell_offsets + atlas.cell_base[m]
    cdef float x = sim.x[i], y = sim.y[i], cell = atlas.grid_cell[m], R = prm.obs_radius
    cdef float gx, gy, margin, r, lo2, hi2
    cdef bint by_count = False
    gx = clamp_cells((x - atlas.grid_origin[2 * m]) / cell)
    gy = clamp_cells((y - atlas.grid_origin[2 * m + 1]) / cell)
    cx = <int>floor(gx)
    cy = <int>floor(gy)
    # every point within `margin` of the agent lies in its own cell; after ring j every point
    # within j * cell + margin has been scanned (the safe radius r)
    margin = min(min(gx - cx, 1.0 - (gx - cx)), min(gy - cy, 1.0 - (gy - cy))) * cell
    while True:
        n = scan_ring(atlas, offs, nx, ny, cx, cy, j, x, y, cand, cd, n, cap)
        r = j * cell + margin
        if r >= R or (cx - j <= 0 and cy - j <= 0 and cx + j >= nx - 1 and cy + j >= ny - 1):
            break
        if n >= maxr and count_within(cd, n, r * r) >= maxr:
            by_count = True  # the nearest max_road all lie within r: farther rings cannot matter
            break
        j += 1
    # every candidate within the previous ring's safe radius is kept unless those alone reach
    # max_road; the selection then only sorts out the last shell
    lo2 = (r - cell) * (r - cell) if r - cell > 0.0 else -1.0
    hi2 = min(r * r, R * R) if by_count else R * R
    return keep_nearest(atlas, cand, cd, n, maxr, lo2, hi2, &sim.road_idx[<int64_t>i * maxr], dmax2)


cdef int scan_disc(const Atlas* atlas, int m, float x, float y, float rad, int32_t* cand, float* cd,
                   int cap) noexcept nogil:
    """Write to (cand, cd) every segment of the grid cells that meet the disc of radius `rad`
    around (x, y), one contiguous run per grid column; return their count."""
    cdef int nx = atlas.grid_nx[m], ny = atlas.grid_ny[m], ix, lo_x, hi_x, lo_y, hi_y, n = 0
    cdef const int32_t* offs = atlas.cell_offsets + atlas.cell_base[m]
    cdef float ox = atlas.grid_origin[2 * m], oy = atlas.grid_origin[2 * m + 1], cell = atlas.grid_cell[m]
    cdef float inv = 1.0 / cell, gx, gy, gr, dx, h
    gx = clamp_cells((x - ox) * inv)
    gy = clamp_cells((y - oy) * inv)
    gr = clamp_reach(rad * inv)
    lo_x = max(<int>floor(gx - gr), 0)
    hi_x = min(<int>floor(gx + gr), nx - 1)
    for ix in range(lo_x, hi_x + 1):
        # distance in cells from the agent to the column [ix, ix + 1)
        dx = max(max(ix - gx, gx - (ix + 1)), 0.0)
        h = gr * gr - dx * dx
        if h < 0.0:
            continue
        h = sqrt(h)
        lo_y = max(<int>floor(gy - h), 0)
        hi_y = min(<int>floor(gy + h), ny - 1)
        if lo_y <= hi_y:
            n = scan_range(atlas, offs[ix * ny + lo_y], offs[ix * ny + hi_y + 1], x, y, cand, cd, n, cap)
    return n


cdef inline float clamp_cells(float g) noexcept nogil:
    """Grid coordinate clamped to +-2^20 cells (NaN to the lower bound): no overflow, no hang."""
    if not g > -1048576.0:
        return -1048576.0
    if g > 1048576.0:
        return 1048576.0
    return g


cdef inline float clamp_reach(float g) noexcept nogil:
    """A search radius in cells, at most 2^22: with the centre clamped to +-2^20 cells the
    column and row bounds stay far inside int (a radius of 1e12 m, accepted as lane_radius or
    obs_radius, used to overflow the conversion and scan nothing); 2^22 cells still cover
    every grid."""
    return g if g < 4194304.0 else 4194304.0


cdef inline int scan_range(const Atlas* atlas, int lo, int hi, float x, float y, int32_t* cand,
                           float* cd, int n, int cap) noexcept nogil:
    """Append atlas positions [lo, hi) and their squared midpoint distances [m^2] (contiguous
    loads, no branch: the compiler vectorizes it); beyond `cap` candidates are dropped."""
    cdef int t, cnt = hi - lo
    cdef float dx, dy
    cdef const float* mx = atlas.seg_mx + lo
    cdef const float* my = atlas.seg_my + lo
    cdef float* d = cd + n
    cdef int32_t* c = cand + n
    if cnt > cap - n:
        cnt = cap - n
    for t in range(cnt):
        dx = mx[t] - x
        dy = my[t] - y
        d[t] = dx * dx + dy * dy
        c[t] = lo + t
    return n + cnt


cdef int scan_ring(const Atlas* atlas, const int32_t* offs, int nx, int ny, int cx, int cy, int j,
                   float x, float y, int32_t* cand, float* cd, int n, int cap) noexcept nogil:
    """Append the segments of the cells at Chebyshev distance j from cell (cx, cy), clipped to
    the grid; a column's cells are contiguous (x-major layout), so a ring is 2 + 2 (2j - 1) runs."""
    cdef int ix, lo_y = max(cy - j, 0), hi_y = min(cy + j, ny - 1)
    if lo_y > hi_y:
        return n
    for ix in range(max(cx - j, 0), min(cx + j, nx - 1) + 1):
        if ix == cx - j or ix == cx + j:
            n = scan_range(atlas, offs[ix * ny + lo_y], offs[ix * ny + hi_y + 1], x, y, cand, cd, n, cap)
        else:
            if cy - j >= 0:
                n = scan_range(atlas, offs[ix * ny + cy - j], offs[ix * ny + cy - j + 1], x, y,
                               cand, cd, n, cap)
            if cy + j < ny:
                n = scan_range(atlas, offs[ix * ny + cy + j], offs[ix * ny + cy + j + 1], x, y,
                               cand, cd, n, cap)
    return n


cdef inline int count_within(const float* cd, int n, float r2) noexcept nogil:
    cdef int t, c = 0
    for t in range(n):
        c += cd[t] <= r2
    return c


cdef void road_events(Sim* sim, const Atlas* atlas, const Params* prm, int w, int i,
                      const int32_t* cand, const float* cand_d, int n, float near2,
                      float lane_far2, float box_r, float moved) noexcept nogil:
    """Road-edge contact, red-light crossing and lane association from the n candidates (atlas
    positions covering every segment within reach of the box and of lane_radius, with their
    squared midpoint distances from the scan in `cand_d`; box_r: the
    box's bounding radius, moved: this step's displacement [m]). Before an exact test, a
    candidate is dropped when its midpoint is farther than the test's reach plus half its
    own length (plus EPAD): then no point of it can pass the test, so no result changes.

    The candidates come in scan order with their types mixed, so a branch per candidate on
    its type and reach is mispredicted often; a branch-free pass first sorts those that pass
    the reach test into one short list per type (chunks of EV_CHUNK), then each list runs its
    exact tests. Every result is order-independent (any contact, any red crossing, the
    nearest centerline with ties to the lower global index), so the lists give the same
    events as one pass in scan order."""
    cdef int t, k, p, g, ty, t0, t1, ok, nl, ne, ng, best_c = -1, best_a = -1
    cdef int32_t lanes[EV_CHUNK]
    cdef int32_t edges[EV_CHUNK]
    cdef int32_t lights[EV_CHUNK]
    cdef float lim[8]
    cdef float reach[8]
    cdef float x = sim.x[i], y = sim.y[i], c = sim.hcos[i], sn = sim.hsin[i], d2, ld, rr
    cdef float hl = 0.5 * sim.length[i], hw = 0.5 * sim.width[i], R2 = prm.obs_radius * prm.obs_radius
    cdef float dc = 1e30, da = 1e30, lr2 = prm.lane_radius * prm.lane_radius, ex, ey
    cdef const float* r
    cdef unsigned char bits = 0
    for t in range(8):
        lim[t] = -1.0  # other types: never listed (d2 >= 0)
        reach[t] = 0.0
    lim[SEG_LANE] = min(lane_far2, R2)
    lim[SEG_EDGE] = min(near2, R2)
    lim[SEG_LIGHT] = min(near2, R2)
    reach[SEG_LANE] = prm.lane_radius + EPAD
    reach[SEG_EDGE] = box_r + EPAD
    reach[SEG_LIGHT] = box_r + moved + EPAD
    for t0 in range(0, n, EV_CHUNK):
        t1 = min(t0 + EV_CHUNK, n)
        nl = ne = ng = 0
        for t in range(t0, t1):
            # counters in registers, each candidate written to all three lists and kept by
            # the one it matches: no branch and no chain through a counter array in memory
            p = cand[t]
            d2 = cand_d[t]
            r = atlas.seg_rec + 8 * p  # the record line the observation rows read next
            ty = (<int>(r[5] * <float>4.0)) & 7  # type / 4, exact; build_atlas checks [0, 8)
            rr = reach[ty] + <float>0.5 * r[6]
            ok = (d2 <= lim[ty]) & (d2 <= rr * rr)
            lanes[nl] = p
            edges[ne] = p
            lights[ng] = p
            nl += ok & (ty == SEG_LANE)
            ne += ok & (ty == SEG_EDGE)
            ng += ok & (ty == SEG_LIGHT)
        for k in range(nl):
            p = lanes[k]
            r = atlas.seg_rec + 8 * p
            ld = point_rec_d2(r, x, y)
            if ld <= lr2:
                # ties go to the lower global segment index (the reference's argmin)
                if r[2] * c + r[3] * sn > 0.0:
                    if ld < dc or (ld == dc and atlas.seg_id[p] < atlas.seg_id[best_c]):
                        dc = ld
                        best_c = p
                if ld < da or (ld == da and atlas.seg_id[p] < atlas.seg_id[best_a]):
                    da = ld
                    best_a = p
        if not bits & EV_OFFROAD:
            for k in range(ne):
                p = edges[k]
                if rec_touches(atlas.seg_rec + 8 * p, x, y, c, sn, hl, hw):
                    bits |= EV_OFFROAD
                    break  # more contacts change nothing
        if not bits & EV_RED:
            for k in range(ng):
                p = lights[k]
                r = atlas.seg_rec + 8 * p
                g = atlas.seg_group[p]
                if g >= 0 and g < sim.G and sim.light_state[w * sim.G + g] == LIGHT_RED:
                    ex = <float>0.5 * r[6] * r[2]
                    ey = <float>0.5 * r[6] * r[3]
                    if rec_touches(r, x, y, c, sn, hl, hw) or segs_cross(
                            sim.px[i], sim.py[i], x, y, r[0] - ex, r[1] - ey, r[0] + ex, r[1] + ey):
                        bits |= EV_RED
                        break
    sim.events[i] |= bits
    associate_lane(sim, atlas, i, best_c if best_c >= 0 else best_a)


cdef int keep_nearest(const Atlas* atlas, int32_t* cand, float* cd, int n, int maxr, float lo2,
                      float hi2, int32_t* out, float* dmax2) noexcept nogil:
    """Write the atlas positions of the (up to) maxr candidates nearest by (distance, global
    index) with squared distance <= hi2 [m^2] to `out` and return their count. Candidates
    within lo2 (fewer than maxr by the caller's bound, checked here) are kept in scan order
    without sorting (the observation does not sort road segments); only the shell (lo2, hi2]
    is partially sorted. Scratch (cand, cd) is reused in place. `dmax2` receives the largest
    kept squared distance when maxr are kept."""
    cdef int t, o = 0, nb = 0, p
    cdef float d
    if lo2 > hi2:
        lo2 = hi2
    if count_within(cd, n, lo2) >= maxr:
        lo2 = -1.0
    # branch-free split: o stays below maxr (the check above), nb <= t (in-place compaction)
    for t in range(n):
        d = cd[t]
        p = cand[t]
        out[o] = p
        o += d <= lo2
        cand[nb] = p
        cd[nb] = d
        nb += (d > lo2) & (d <= hi2)
    return append_shell(atlas, out, o, cand, cd, nb, maxr, max(lo2, 0.0), hi2, dmax2)


cdef inline int append_shell(const Atlas* atlas, int32_t* out, int ni, int32_t* shell,
                             float* shell_d, int ns, int maxr, float lo2, float hi2,
                             float* dmax2) noexcept nogil:
    """After the ni inner candidates in `out`, append the nearest of the ns shell candidates
    (squared distances in [lo2, hi2]) up to maxr in all; returns the count kept. `dmax2`
    receives the largest appended squared distance: with maxr kept at least one comes from
    the shell, whose entries are the farthest."""
    cdef int t, keep = min(ni + ns, maxr), b = keep - ni
    cdef float big = 0.0
    if b < ns:
        # ties by global index, looked up only on a tie
        select_nearest_binned(shell_d, shell, ns, b, lo2, hi2, atlas.seg_id)
    for t in range(b):
        out[ni + t] = shell[t]
        big = shell_d[t] if shell_d[t] > big else big
    dmax2[0] = big
    return keep


cdef inline bint rec_touches(const float* r, float x, float y, float c, float sn, float hl,
                             float hw) noexcept nogil:
    """The segment of record r (sim/atlas.py `seg_rec`: midpoint, unit direction, length)
    touches the box: its endpoints are midpoint -/+ half the length along the direction."""
    cdef float ex = <float>0.5 * r[6] * r[2], ey = <float>0.5 * r[6] * r[3]
    return seg_box(r[0] - ex, r[1] - ey, r[0] + ex, r[1] + ey, x, y, c, sn, hl, hw)


cdef inline float point_rec_d2(const float* r, float x, float y) noexcept nogil:
    """Squared distance [m^2] from (x, y) to the segment of record r: the projection on the
    direction from the midpoint, clamped to half the length on either side."""
    cdef float ux = x - r[0], uy = y - r[1], dx = r[2], dy = r[3], h = <float>0.5 * r[6]
    cdef float t = ux * dx + uy * dy
    if t < -h:
        t = -h
    elif t > h:
        t = h
    ux = ux - t * dx
    uy = uy - t * dy
    return ux * ux + uy * uy


cdef void associate_lane(Sim* sim, const Atlas* atlas, int i, int s) noexcept nogil:
    """Signed lateral offset s (+ right of the lane direction) and angle alpha of agent i to
    centerline segment `s` (section 2.3); no lane within `lane_radius` gives s = alpha = 0."""
    cdef float dx, dy, ux, uy, c = sim.hcos[i], sn = sim.hsin[i]
    cdef const float* r
    if s < 0:
        sim.lane_valid[i] = 0
        sim.lane_s[i] = 0.0
        sim.lane_alpha[i] = 0.0
        return
    # offset from the midpoint: the same lateral offset as from the start (both on the line)
    r = atlas.seg_rec + 8 * s
    dx = r[2]
    dy = r[3]
    ux = sim.x[i] - r[0]
    uy = sim.y[i] - r[1]
    sim.lane_valid[i] = 1
    sim.lane_s[i] = ux * dy - uy * dx
    # the one atan2 per agent: alpha is needed as an angle by the alignment reward
    sim.lane_alpha[i] = atan2f(dx * sn - dy * c, dx * c + dy * sn)
