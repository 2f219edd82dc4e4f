# cython: language_level=3
"""Events of one step (paper sections 2.2-2.3): traffic lights and pedestrians advance,
vehicle and pedestrian collisions on the true oriented boxes, and one road gather per agent
that feeds road-edge contact, red-light crossing, lane association and the road observation.
"""

from libc.math cimport sqrt, ceil, floor, atan2, cos, sin, fabs
from libc.stdint cimport int32_t, int64_t
from selfplaydrive._sim.common cimport (Sim, Params, Atlas, SEG_LANE, SEG_EDGE, SEG_LIGHT,
                                        LIGHT_RED, EV_COLLIDE, EV_PED, EV_OFFROAD, EV_RED,
                                        EV_WAYPOINT, EV_COMFORT, C_RADIUS)
from selfplaydrive._sim.geometry cimport (obb_overlap, seg_box, segs_cross, box_radius,
                                          wrap_angle, select_nearest_binned)
from selfplaydrive._sim.rng cimport rng_int, rng_uniform


cdef void lights_peds_world(Sim* sim, const Params* prm, int w) noexcept nogil:
    """Advance the episode clock, the signal groups and the pedestrians of world `w`."""
    cdef int g, i
    sim.step[w] += 1
    if sim.lights_on[w]:
        for g in range(sim.G):
            i = w * sim.G + g
            sim.light_time[i] -= prm.dt
            if sim.light_time[i] <= 0.0:
                # a random state (off/red/yellow/green) for U(light_min, light_max) s (section 2.2)
                sim.light_state[i] = <char>rng_int(sim.rng_key[w], &sim.rng_ctr[w], 4)
                sim.light_time[i] = prm.light_min + (prm.light_max - prm.light_min) * rng_uniform(
                    sim.rng_key[w], &sim.rng_ctr[w])
    peds_world(sim, prm, w)


cdef void peds_world(Sim* sim, const Params* prm, int w) noexcept nogil:
    """Place the pedestrians of world `w` at the episode time step * dt."""
    cdef int k
    cdef float t = sim.step[w] * prm.dt
    for k in range(sim.P):
        place_pedestrian(sim, prm, w * sim.P + k, t)


cdef void place_pedestrian(Sim* sim, const Params* prm, int i, float t) noexcept nogil:
    """Put pedestrian i where its path puts it at time t: waiting at the first point before its
    start time, walking at its speed, then standing at (or vanishing from) the last point."""
    cdef const float* path = sim.ped_path + i * sim.T * 2
    cdef int n = sim.ped_np[i], k
    cdef float todo, dx = 0.0, dy = 0.0, seg = 0.0, f, vx = 0.0, vy = 0.0
    sim.ped_px[i] = sim.ped_x[i]
    sim.ped_py[i] = sim.ped_y[i]
    if not sim.ped_valid[i] or n < 2:
        return
    todo = (t - sim.ped_start[i]) * sim.ped_speed[i]
    if todo < 0.0:
        todo = 0.0
    for k in range(n - 1):
        dx = path[2 * k + 2] - path[2 * k]
        dy = path[2 * k + 3] - path[2 * k + 1]
        seg = sqrt(dx * dx + dy * dy)
        if todo < seg or k == n - 2:
            break
        todo -= seg
    if seg > 0.0:
        sim.ped_cos[i] = dx / seg
        sim.ped_sin[i] = dy / seg
    if todo >= seg:
        f = 1.0
        if prm.ped_vanish:
            sim.ped_here[i] = 0
    else:
        f = todo / seg
        if t >= sim.ped_start[i]:
            vx = sim.ped_speed[i] * dx / seg
            vy = sim.ped_speed[i] * dy / seg
    sim.ped_x[i] = path[2 * k] + f * dx
    sim.ped_y[i] = path[2 * k + 1] + f * dy
    sim.ped_vx[i] = vx
    sim.ped_vy[i] = vy


cdef bint swept_overlap(float ax0, float ay0, float ah0, float ax1, float ay1, float ah1,
                        float ac, float as_, float ahl, float ahw,
                        float bx0, float by0, float bh0, float bx1, float by1, float bh1,
                        float bc, float bs, float bhl, float bhw, int max_sub) noexcept nogil:
    """Boxes A and B overlap at the end of the step or, when their relative motion exceeds the
    smaller box extent, at any of ceil(motion / extent) evenly spaced sub-steps (no tunnelling)."""
    cdef float rdx = (ax1 - ax0) - (bx1 - bx0), rdy = (ay1 - ay0) - (by1 - by0)
    cdef float rel = sqrt(rdx * rdx + rdy * rdy)
    cdef float dx = bx1 - ax1, dy = by1 - ay1, reach, ext, f, dha, dhb
    cdef float ca = ac, sa = as_, cb = bc, sb = bs
    cdef int n, k
    reach = box_radius(ahl, ahw) + box_radius(bhl, bhw) + rel
    if dx * dx + dy * dy > reach * reach:
        return False
    if obb_overlap(ax1, ay1, ac, as_, ahl, ahw, bx1, by1, bc, bs, bhl, bhw):
        return True
    ext = 2.0 * min(min(ahl, ahw), min(bhl, bhw))
    if rel <= ext:
        return False
    n = <int>ceil(rel / ext)
    if n > max_sub:
        n = max_sub
    dha = wrap_angle(ah1 - ah0)
    dhb = wrap_angle(bh1 - bh0)
    for k in range(1, n):
        f = <float>k / n
        # a body that does not turn keeps its final cos/sin (no trig for statics, pedestrians)
        if dha != 0.0:
            ca = cos(ah0 + f * dha)
            sa = sin(ah0 + f * dha)
        if dhb != 0.0:
            cb = cos(bh0 + f * dhb)
            sb = sin(bh0 + f * dhb)
        if obb_overlap(ax0 + f * (ax1 - ax0), ay0 + f * (ay1 - ay0), ca, sa, ahl, ahw,
                       bx0 + f * (bx1 - bx0), by0 + f * (by1 - by0), cb, sb, bhl, bhw):
            return True
    return False


cdef inline bint agents_hit(Sim* sim, int i, int j, int max_sub) noexcept nogil:
    return swept_overlap(sim.px[i], sim.py[i], sim.pheading[i], sim.x[i], sim.y[i], sim.heading[i],
                         sim.hcos[i], sim.hsin[i], 0.5 * sim.length[i], 0.5 * sim.width[i],
                         sim.px[j], sim.py[j], sim.pheading[j], sim.x[j], sim.y[j], sim.heading[j],
                         sim.hcos[j], sim.hsin[j], 0.5 * sim.length[j], 0.5 * sim.width[j], max_sub)


cdef void collisions_world(Sim* sim, const Params* prm, int w) noexcept nogil:
    """Set EV_COLLIDE / EV_PED on active agents of world `w` whose box meets another body.

    Bodies: active agents, ended agents kept as obstacles, static vehicles, pedestrians.
    """
    cdef int a, b, i, j, k, n = sim.A
    for a in range(n):
        i = w * n + a
        if not (sim.active[i] or sim.obstacle[i]):
            continue
        for b in range(a + 1, n):
            j = w * n + b
            if not (sim.active[j] or sim.obstacle[j]) or not (sim.active[i] or sim.active[j]):
                continue
            if agents_hit(sim, i, j, prm.max_substeps):
                if sim.active[i]:
                    sim.events[i] |= EV_COLLIDE
                if sim.active[j]:
                    sim.events[j] |= EV_COLLIDE
        if not sim.active[i]:
            continue
        for k in range(w * sim.S, (w + 1) * sim.S):
            if sim.st_valid[k] and swept_overlap(
                    sim.px[i], sim.py[i], sim.pheading[i], sim.x[i], sim.y[i], sim.heading[i],
                    sim.hcos[i], sim.hsin[i], 0.5 * sim.length[i], 0.5 * sim.width[i],
                    sim.st_x[k], sim.st_y[k], 0.0, sim.st_x[k], sim.st_y[k], 0.0,
                    sim.st_cos[k], sim.st_sin[k], 0.5 * sim.st_len[k], 0.5 * sim.st_wid[k],
                    prm.max_substeps):
                sim.events[i] |= EV_COLLIDE
        for k in range(w * sim.P, (w + 1) * sim.P):
            if sim.ped_valid[k] and sim.ped_here[k]:
                if swept_overlap(
                        sim.px[i], sim.py[i], sim.pheading[i], sim.x[i], sim.y[i], sim.heading[i],
                        sim.hcos[i], sim.hsin[i], 0.5 * sim.length[i], 0.5 * sim.width[i],
                        sim.ped_px[k], sim.ped_py[k], 0.0, sim.ped_x[k], sim.ped_y[k], 0.0,
                        sim.ped_cos[k], sim.ped_sin[k], 0.5 * sim.ped_len[k], 0.5 * sim.ped_wid[k],
                        prm.max_substeps):
                    sim.events[i] |= EV_PED


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
    cdef int m = sim.map_id[w], ix, iy, lo_x, hi_x, lo_y, hi_y, nx, ny, n = 0, s, keep
    cdef int best_c = -1, best_a = -1, t, g, cap = sim.cand_cap
    cdef int64_t base = atlas.cell_base[m], c0, k
    cdef float x = sim.x[i], y = sim.y[i], c = sim.hcos[i], sn = sim.hsin[i]
    cdef float hl = 0.5 * sim.length[i], hw = 0.5 * sim.width[i], R = prm.obs_radius
    cdef float ox = atlas.grid_origin[2 * m], oy = atlas.grid_origin[2 * m + 1], cell = atlas.grid_cell[m]
    cdef float half_seg = 0.5 * atlas.max_seg_len[m], mx, my, d2, near, lane_far, dc = 1e30, da = 1e30
    cdef float dpx = x - sim.px[i], dpy = y - sim.py[i], ld
    cdef int32_t* cand = sim.cand + <int64_t>w * cap
    cdef float* cd = sim.cand_d + <int64_t>w * cap
    cdef unsigned char bits = 0
    near = box_radius(hl, hw) + half_seg + sqrt(dpx * dpx + dpy * dpy)
    near = near * near
    lane_far = prm.lane_radius + half_seg
    lane_far = lane_far * lane_far
    nx = atlas.grid_nx[m]
    ny = atlas.grid_ny[m]
    lo_x = max(0, <int>floor((x - R - ox) / cell))
    hi_x = min(nx - 1, <int>floor((x + R - ox) / cell))
    lo_y = max(0, <int>floor((y - R - oy) / cell))
    hi_y = min(ny - 1, <int>floor((y + R - oy) / cell))
    for ix in range(lo_x, hi_x + 1):
        c0 = base + ix * ny
        for k in range(atlas.cell_offsets[c0 + lo_y], atlas.cell_offsets[c0 + hi_y + 1]):
            s = atlas.cell_items[k]
            mx = atlas.seg_mid[2 * s] - x
            my = atlas.seg_mid[2 * s + 1] - y
            d2 = mx * mx + my * my
            if d2 > R * R:
                continue
            if n < cap:
                cand[n] = s
                cd[n] = d2
                n += 1
            if d2 > near and d2 > lane_far:
                continue
            t = atlas.seg_type[s]
            if t == SEG_LANE:
                if d2 <= lane_far:
                    ld = point_seg_d2(atlas, s, x, y)
                    if ld <= prm.lane_radius * prm.lane_radius:
                        if atlas.seg_dir[2 * s] * c + atlas.seg_dir[2 * s + 1] * sn > 0.0:
                            if ld < dc:
                                dc = ld
                                best_c = s
                        if ld < da:
                            da = ld
                            best_a = s
            elif d2 <= near and t == SEG_EDGE:
                if box_touches(atlas, s, x, y, c, sn, hl, hw):
                    bits |= EV_OFFROAD
            elif d2 <= near and t == SEG_LIGHT:
                g = atlas.seg_group[s]
                if g >= 0 and g < sim.G and sim.light_state[w * sim.G + g] == LIGHT_RED:
                    if box_touches(atlas, s, x, y, c, sn, hl, hw) or segs_cross(
                            sim.px[i], sim.py[i], x, y, atlas.seg_start[2 * s], atlas.seg_start[2 * s + 1],
                            atlas.seg_end[2 * s], atlas.seg_end[2 * s + 1]):
                        bits |= EV_RED
    sim.events[i] |= bits
    associate_lane(sim, atlas, i, best_c if best_c >= 0 else best_a)
    keep = min(n, sim.max_road)
    select_nearest_binned(cd, cand, n, keep, R * R)
    for k in range(keep):
        sim.road_idx[<int64_t>i * sim.max_road + k] = cand[k]
    sim.road_n[i] = keep


cdef inline bint box_touches(const Atlas* atlas, int s, float x, float y, float c, float sn,
                             float hl, float hw) noexcept nogil:
    return seg_box(atlas.seg_start[2 * s], atlas.seg_start[2 * s + 1], atlas.seg_end[2 * s],
                   atlas.seg_end[2 * s + 1], x, y, c, sn, hl, hw)


cdef inline float point_seg_d2(const Atlas* atlas, int s, float x, float y) noexcept nogil:
    """Squared distance [m^2] from (x, y) to segment s."""
    cdef float ux = x - atlas.seg_start[2 * s], uy = y - atlas.seg_start[2 * s + 1]
    cdef float dx = atlas.seg_dir[2 * s], dy = atlas.seg_dir[2 * s + 1]
    cdef float t = ux * dx + uy * dy
    if t < 0.0:
        t = 0.0
    elif t > atlas.seg_len[s]:
        t = atlas.seg_len[s]
    ux = ux - t * dx
    uy = uy - t * dy
    return ux * ux + uy * uy


cdef void associate_lane(Sim* sim, const Atlas* atlas, int i, int s) noexcept nogil:
    """Signed lateral offset s (+ right of the lane direction) and angle alpha of agent i to
    centerline segment `s` (section 2.3); no lane within `lane_radius` gives s = alpha = 0."""
    cdef float dx, dy, ux, uy, c = sim.hcos[i], sn = sim.hsin[i]
    if s < 0:
        sim.lane_valid[i] = 0
        sim.lane_s[i] = 0.0
        sim.lane_alpha[i] = 0.0
        return
    dx = atlas.seg_dir[2 * s]
    dy = atlas.seg_dir[2 * s + 1]
    ux = sim.x[i] - atlas.seg_start[2 * s]
    uy = sim.y[i] - atlas.seg_start[2 * s + 1]
    sim.lane_valid[i] = 1
    sim.lane_s[i] = ux * dy - uy * dx
    # the one atan2 per agent: alpha is needed as an angle by the alignment reward
    sim.lane_alpha[i] = atan2(dx * sn - dy * c, dx * c + dy * sn)
