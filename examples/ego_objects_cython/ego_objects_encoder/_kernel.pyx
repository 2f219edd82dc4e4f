# cython: language_level=3
"""Ego + the k nearest bodies as an `sd_encoder_fn` (selfplaydrive_abi.h): the loop of the numba
form (examples/09_encoder_numba.py) in float32, line for line."""

from libc.math cimport INFINITY, M_PI
from libc.stdint cimport int32_t, int64_t
from selfplaydrive_abi cimport Sim, Params, Atlas, EGO_DIM, OBJ_DIM, NUM_COEFFS


cdef inline float clip(float v) noexcept nogil:
    return 1.0 if v > 1.0 else (-1.0 if v < -1.0 else v)


cdef void ego_objects(const Sim* sim, const Params* prm, const Atlas* atlas, const void* args,
                      int32_t w, float* out, int32_t stride) noexcept nogil:
    """Ego features as the paper's, then the k = sim.max_obj nearest bodies within obs_radius
    as the paper's object rows (nearest first, ties to the lower body index); zero padding."""
    cdef int A = sim.A, S = sim.S, P = sim.P, K = sim.K, NB = sim.A + sim.S + sim.P
    cdef int a, i, j, b, t, f, k, n, k1, best
    cdef int64_t o, r
    cdef float* dist = sim.cand_d + <int64_t>w * sim.cand_cap   # the world's scratch
    cdef float c, s, ex, ey, ux, uy, d0x, d0y, d1x, d1y, dx, dy, d2, bd, R2
    cdef float bx, by, bc, bs, vx, vy, bl, bw
    R2 = prm.obs_radius * prm.obs_radius
    for a in range(A):
        i = w * A + a
        if not sim.active[i]:
            continue
        o = <int64_t>a * stride
        c = sim.hcos[i]; s = sim.hsin[i]; ex = sim.x[i]; ey = sim.y[i]
        k = sim.wp_idx[i]; n = sim.num_wp[i]
        d0x = 0.0; d0y = 0.0; d1x = 0.0; d1y = 0.0
        if k < n:
            k1 = k + 1 if k + 1 < n else k
            ux = sim.waypoints[(i * K + k) * 2] - ex; uy = sim.waypoints[(i * K + k) * 2 + 1] - ey
            d0x = c * ux + s * uy; d0y = -s * ux + c * uy
            ux = sim.waypoints[(i * K + k1) * 2] - ex; uy = sim.waypoints[(i * K + k1) * 2 + 1] - ey
            d1x = c * ux + s * uy; d1y = -s * ux + c * uy
        out[o + 0] = clip(sim.width[i] / prm.width_scale)
        out[o + 1] = clip(sim.length[i] / prm.length_scale)
        out[o + 2] = clip(sim.speed[i] / prm.max_speed)
        out[o + 3] = clip(d0x / prm.wp_scale); out[o + 4] = clip(d0y / prm.wp_scale)
        out[o + 5] = clip(d1x / prm.wp_scale); out[o + 6] = clip(d1y / prm.wp_scale)
        out[o + 7] = clip(<float>(n - k) / <float>K) if K > 0 else 0.0
        out[o + 8] = clip(sim.lane_s[i] / prm.lateral_scale)
        out[o + 9] = clip(sim.lane_alpha[i] / <float>M_PI)
        out[o + 10] = sim.lane_valid[i]
        for j in range(NUM_COEFFS):
            out[o + 11 + j] = clip(sim.coeffs[i * NUM_COEFFS + j] / prm.coeff_scale[j])
        for b in range(NB):
            dx = INFINITY; dy = INFINITY
            if b < A:
                j = w * A + b
                if b != a and (sim.active[j] or sim.obstacle[j]):
                    dx = sim.x[j] - ex; dy = sim.y[j] - ey
            elif b < A + S:
                j = w * S + b - A
                if sim.st_valid[j]:
                    dx = sim.st_x[j] - ex; dy = sim.st_y[j] - ey
            else:
                j = w * P + b - A - S
                if sim.ped_valid[j] and sim.ped_here[j]:
                    dx = sim.ped_x[j] - ex; dy = sim.ped_y[j] - ey
            d2 = dx * dx + dy * dy
            dist[b] = d2 if d2 <= R2 else INFINITY
        for t in range(sim.max_obj):
            r = o + EGO_DIM + t * OBJ_DIM
            best = -1
            bd = INFINITY
            for b in range(NB):
                if dist[b] < bd:
                    best = b
                    bd = dist[b]
            if best < 0:
                for f in range(OBJ_DIM):
                    out[r + f] = 0.0
                continue
            dist[best] = INFINITY
            if best < A:
                j = w * A + best
                bx = sim.x[j]; by = sim.y[j]; bc = sim.hcos[j]; bs = sim.hsin[j]
                vx = sim.speed[j] * sim.hcos[j]; vy = sim.speed[j] * sim.hsin[j]
                bl = sim.length[j]; bw = sim.width[j]
            elif best < A + S:
                j = w * S + best - A
                bx = sim.st_x[j]; by = sim.st_y[j]; bc = sim.st_cos[j]; bs = sim.st_sin[j]
                vx = 0.0; vy = 0.0; bl = sim.st_len[j]; bw = sim.st_wid[j]
            else:
                j = w * P + best - A - S
                bx = sim.ped_x[j]; by = sim.ped_y[j]; bc = sim.ped_cos[j]; bs = sim.ped_sin[j]
                vx = sim.ped_vx[j]; vy = sim.ped_vy[j]; bl = sim.ped_len[j]; bw = sim.ped_wid[j]
            ux = bx - ex; uy = by - ey
            out[r + 0] = 1.0
            out[r + 1] = clip((c * ux + s * uy) / prm.pos_scale)
            out[r + 2] = clip((-s * ux + c * uy) / prm.pos_scale)
            out[r + 3] = clip(bc * c + bs * s)
            out[r + 4] = clip(bs * c - bc * s)
            out[r + 5] = clip(bl / prm.length_scale)
            out[r + 6] = clip(bw / prm.width_scale)
            out[r + 7] = clip((c * vx + s * vy) / prm.max_speed)
            out[r + 8] = clip((-s * vx + c * vy) / prm.max_speed)
