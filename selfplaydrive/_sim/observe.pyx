# cython: language_level=3
"""Observations (paper section 2.5), written once per active agent row, padding included (no
buffer-wide clearing). Layout and feature names: selfplaydrive/sim/layout.py. Every value is
scaled and clipped to [-1, 1]; positions and directions are in the ego frame (x forward,
y left)."""

from libc.stdint cimport int32_t, int64_t
from selfplaydrive._sim.common cimport (Sim, Params, Atlas, EGO_DIM, OBJ_DIM, ROAD_DIM,
                                        NUM_COEFFS, SEG_LIGHT)
from selfplaydrive._sim.geometry cimport select_nearest


cdef inline float clip(float v) noexcept nogil:
    if v > 1.0:
        return 1.0
    if v < -1.0:
        return -1.0
    return v


cdef void observe_world(Sim* sim, const Atlas* atlas, const Params* prm, int w) noexcept nogil:
    """Write the observation row of every active agent of world `w`."""
    cdef int a, i
    cdef float* row
    for a in range(sim.A):
        i = w * sim.A + a
        if sim.active[i]:
            row = &sim.obs[<int64_t>i * sim.obs_dim]
            write_ego(sim, prm, i, row)
            write_objects(sim, prm, w, i, row + EGO_DIM)
            write_road(sim, atlas, prm, w, i, row + EGO_DIM + sim.max_obj * OBJ_DIM)


cdef void write_ego(Sim* sim, const Params* prm, int i, float* o) noexcept nogil:
    cdef int k = sim.wp_idx[i], n = sim.num_wp[i], j
    cdef float c = sim.hcos[i], s = sim.hsin[i], dx0 = 0.0, dy0 = 0.0, dx1 = 0.0, dy1 = 0.0
    if k < n:
        ego_xy(sim, i, k, c, s, &dx0, &dy0)
        ego_xy(sim, i, k + 1 if k + 1 < n else k, c, s, &dx1, &dy1)
    o[0] = clip(sim.width[i] / prm.width_scale)
    o[1] = clip(sim.length[i] / prm.length_scale)
    o[2] = clip(sim.speed[i] / prm.max_speed)
    o[3] = clip(dx0 / prm.wp_scale)
    o[4] = clip(dy0 / prm.wp_scale)
    o[5] = clip(dx1 / prm.wp_scale)
    o[6] = clip(dy1 / prm.wp_scale)
    o[7] = clip(<float>(n - k) / sim.K) if sim.K > 0 else 0.0
    o[8] = clip(sim.lane_s[i] / prm.lateral_scale)
    o[9] = clip(sim.lane_alpha[i] / 3.14159265358979)
    o[10] = sim.lane_valid[i]
    for j in range(NUM_COEFFS):
        o[11 + j] = clip(sim.coeffs[i * NUM_COEFFS + j] / prm.coeff_scale[j])


cdef inline void ego_xy(Sim* sim, int i, int k, float c, float s, float* dx, float* dy) noexcept nogil:
    cdef float ux = sim.waypoints[(i * sim.K + k) * 2] - sim.x[i]
    cdef float uy = sim.waypoints[(i * sim.K + k) * 2 + 1] - sim.y[i]
    dx[0] = c * ux + s * uy
    dy[0] = -s * ux + c * uy


cdef void write_objects(Sim* sim, const Params* prm, int w, int i, float* o) noexcept nogil:
    """The `max_obj` nearest bodies within obs_radius: other agents (active or obstacles),
    static vehicles and pedestrians, class not observed (section 2.5)."""
    cdef int32_t* cand = sim.cand + <int64_t>w * sim.cand_cap
    cdef float* cd = sim.cand_d + <int64_t>w * sim.cand_cap
    cdef int n = 0, k, j, code, A = sim.A, S = sim.S
    cdef float x = sim.x[i], y = sim.y[i], R2 = prm.obs_radius * prm.obs_radius, dx, dy, d2
    for k in range(A):
        j = w * A + k
        if j != i and (sim.active[j] or sim.obstacle[j]):
            dx = sim.x[j] - x
            dy = sim.y[j] - y
            d2 = dx * dx + dy * dy
            if d2 <= R2:
                cand[n] = k
                cd[n] = d2
                n += 1
    for k in range(S):
        j = w * S + k
        if sim.st_valid[j]:
            dx = sim.st_x[j] - x
            dy = sim.st_y[j] - y
            d2 = dx * dx + dy * dy
            if d2 <= R2:
                cand[n] = A + k
                cd[n] = d2
                n += 1
    for k in range(sim.P):
        j = w * sim.P + k
        if sim.ped_valid[j] and sim.ped_here[j]:
            dx = sim.ped_x[j] - x
            dy = sim.ped_y[j] - y
            d2 = dx * dx + dy * dy
            if d2 <= R2:
                cand[n] = A + S + k
                cd[n] = d2
                n += 1
    if n > sim.max_obj:
        select_nearest(cd, cand, n, sim.max_obj)
        n = sim.max_obj
    for k in range(n):
        object_row(sim, prm, w, i, cand[k], o + k * OBJ_DIM)
    for k in range(n * OBJ_DIM, sim.max_obj * OBJ_DIM):
        o[k] = 0.0


cdef void object_row(Sim* sim, const Params* prm, int w, int i, int code, float* o) noexcept nogil:
    cdef float ox, oy, oc, os, ln, wd, vx, vy, c = sim.hcos[i], s = sim.hsin[i], ux, uy
    cdef int j
    if code < sim.A:
        j = w * sim.A + code
        ox = sim.x[j]; oy = sim.y[j]; oc = sim.hcos[j]; os = sim.hsin[j]
        ln = sim.length[j]; wd = sim.width[j]
        vx = sim.speed[j] * oc; vy = sim.speed[j] * os
    elif code < sim.A + sim.S:
        j = w * sim.S + code - sim.A
        ox = sim.st_x[j]; oy = sim.st_y[j]; oc = sim.st_cos[j]; os = sim.st_sin[j]
        ln = sim.st_len[j]; wd = sim.st_wid[j]
        vx = 0.0; vy = 0.0
    else:
        j = w * sim.P + code - sim.A - sim.S
        ox = sim.ped_x[j]; oy = sim.ped_y[j]; oc = sim.ped_cos[j]; os = sim.ped_sin[j]
        ln = sim.ped_len[j]; wd = sim.ped_wid[j]
        vx = sim.ped_vx[j]; vy = sim.ped_vy[j]
    ux = ox - sim.x[i]
    uy = oy - sim.y[i]
    o[0] = 1.0
    o[1] = clip((c * ux + s * uy) / prm.pos_scale)
    o[2] = clip((-s * ux + c * uy) / prm.pos_scale)
    o[3] = clip(oc * c + os * s)    # cos of the relative heading (clip: float rounding)
    o[4] = clip(os * c - oc * s)    # sin of the relative heading
    o[5] = clip(ln / prm.length_scale)
    o[6] = clip(wd / prm.width_scale)
    o[7] = clip((c * vx + s * vy) / prm.max_speed)
    o[8] = clip((-s * vx + c * vy) / prm.max_speed)


cdef void write_road(Sim* sim, const Atlas* atlas, const Params* prm, int w, int i, float* o) noexcept nogil:
    """The segments chosen by the events gather (road_idx): midpoint, direction (cos, sin, no
    trig: the directions are precomputed), length, type and traffic-light state."""
    cdef int n = sim.road_n[i], k, sg, g
    cdef const int32_t* idx = &sim.road_idx[<int64_t>i * sim.max_road]
    cdef float c = sim.hcos[i], s = sim.hsin[i], ux, uy, dx, dy, st
    cdef float* r
    for k in range(n):
        sg = idx[k]
        r = o + k * ROAD_DIM
        ux = atlas.seg_mid[2 * sg] - sim.x[i]
        uy = atlas.seg_mid[2 * sg + 1] - sim.y[i]
        dx = atlas.seg_dir[2 * sg]
        dy = atlas.seg_dir[2 * sg + 1]
        st = 0.0
        if atlas.seg_type[sg] == SEG_LIGHT:
            g = atlas.seg_group[sg]
            if g >= 0 and g < sim.G:
                st = sim.light_state[w * sim.G + g] / 3.0
        r[0] = 1.0
        r[1] = clip((c * ux + s * uy) / prm.pos_scale)
        r[2] = clip((-s * ux + c * uy) / prm.pos_scale)
        r[3] = clip(dx * c + dy * s)
        r[4] = clip(dy * c - dx * s)
        r[5] = clip(atlas.seg_len[sg] / prm.length_scale)
        r[6] = atlas.seg_type[sg] / 4.0
        r[7] = st
    for k in range(n * ROAD_DIM, sim.max_road * ROAD_DIM):
        o[k] = 0.0
