# cython: language_level=3
"""Events of one step (paper sections 2.2-2.3): traffic lights and pedestrians advance,
vehicle and pedestrian collisions on the true oriented boxes. The road events and the road
gather of the observation are in road.pyx.
"""

from libc.math cimport sqrt, ceil, cos, sin, NAN
from libc.stdint cimport int64_t
from selfplaydrive._sim.common cimport Sim, Params, EV_COLLIDE, EV_PED
from selfplaydrive._sim.geometry cimport obb_overlap, box_radius, wrap_angle
from selfplaydrive._sim.rng cimport rng_int, rng_uniform



cdef void lights_peds_world(Sim* sim, const Params* prm, int w) noexcept nogil:
    """Advance the episode clock, the signal groups and the pedestrians of world `w`."""
    cdef int g, i
    sim.step[w] += 1
    if sim.lights_on[w]:
        for g in range(sim.G):
            i = w * sim.G + g
            sim.light_time[i] -= prm.dt
            # the change falls on the step nearest its scheduled time (less than half a step
            # left), not the first one past it: a drawn duration d in [light_min, light_max)
            # then lasts round(d / dt) steps, which float32 rounding of the countdown cannot
            # push outside [light_min, light_max] (section 2.2: 0.5-10 s)
            if sim.light_time[i] <= 0.5 * prm.dt:
                change_light(sim, prm, w, i)
    peds_world(sim, prm, w)


cdef inline void change_light(Sim* sim, const Params* prm, int w, int i) noexcept nogil:
    """Switch signal group i of world `w` to one of the 3 other states (off/red/yellow/green),
    uniformly, for U(light_min, light_max) s. Never the same state again: a repeat would
    extend the state past light_max (section 2.2: each state lasts 0.5-10 s)."""
    cdef int step = 1 + rng_int(sim.rng_key[w], &sim.rng_ctr[w], 3)
    sim.light_state[i] = <char>((sim.light_state[i] + step) % 4)
    sim.light_time[i] = prm.light_min + (prm.light_max - prm.light_min) * rng_uniform(
        sim.rng_key[w], &sim.rng_ctr[w])


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


cdef extern from "near.h" nogil:
    int spd_near4(const float* bx, const float* by, const float* br, int k, float x0, float y0,
                  float r0)


cdef inline int pad4(int n) noexcept nogil:
    return (n + 3) & ~3


cdef void collisions_world(Sim* sim, const Params* prm, int w) noexcept nogil:
    """Set EV_COLLIDE / EV_PED on active agents of world `w` whose box meets another body.

    Bodies: active agents, ended agents kept as obstacles, static vehicles, pedestrians. A
    pair is tested exactly (`swept_overlap`) only when the final centres lie within the sum of
    both swept radii (bounding radius + this step's motion) with a relative slack, a bound
    that is never smaller than swept_overlap's own early-out distance: the pre-test changes
    no result. The pre-test runs four bodies at a time (near.h) on a struct-of-arrays copy
    of the world's bodies (`body_soa`), in the original pair order.
    """
    cdef int a, b, i, j, k, l, m, n = sim.A, S = sim.S, P = sim.P, nA = pad4(sim.A)
    cdef int nS = pad4(sim.S), nP = pad4(sim.P), k0
    cdef float* ax = sim.cand_d + <int64_t>w * sim.cand_cap   # scratch, see body_soa
    cdef float* ay = ax + nA
    cdef float* ar = ay + nA
    cdef float* sx = ar + nA
    cdef float* sy = sx + nS
    cdef float* sr = sy + nS
    cdef float* qx = sr + nS
    cdef float* qy = qx + nP
    cdef float* qr = qy + nP
    cdef float x0, y0, r0
    body_soa(sim, w, ax, nA, sx, nS, qx, nP)
    for a in range(n):
        i = w * n + a
        if not (sim.active[i] or sim.obstacle[i]):
            continue
        x0 = ax[a]
        y0 = ay[a]
        r0 = ar[a]
        k0 = (a + 1) & ~3
        for k in range(k0, nA, 4):
            m = spd_near4(ax, ay, ar, k, x0, y0, r0)
            if k == k0:
                m &= ~((1 << (a + 1 - k0)) - 1)  # pairs (a, b) with b > a only
            if m == 0:
                continue
            for l in range(4):
                if not (m >> l) & 1:
                    continue
                b = k + l
                j = w * n + b
                if not (sim.active[i] or sim.active[j]):
                    continue
                if agents_hit(sim, i, j, prm.max_substeps):
                    if sim.active[i]:
                        sim.events[i] |= EV_COLLIDE
                    if sim.active[j]:
                        sim.events[j] |= EV_COLLIDE
        if not sim.active[i]:
            continue
        for k in range(0, nS, 4):
            m = spd_near4(sx, sy, sr, k, x0, y0, r0)
            if m == 0:
                continue
            for l in range(4):
                if not (m >> l) & 1:
                    continue
                j = w * S + k + l
                if swept_overlap(
                        sim.px[i], sim.py[i], sim.pheading[i], sim.x[i], sim.y[i], sim.heading[i],
                        sim.hcos[i], sim.hsin[i], 0.5 * sim.length[i], 0.5 * sim.width[i],
                        sim.st_x[j], sim.st_y[j], 0.0, sim.st_x[j], sim.st_y[j], 0.0,
                        sim.st_cos[j], sim.st_sin[j], 0.5 * sim.st_len[j], 0.5 * sim.st_wid[j],
                        prm.max_substeps):
                    sim.events[i] |= EV_COLLIDE
        for k in range(0, nP, 4):
            m = spd_near4(qx, qy, qr, k, x0, y0, r0)
            if m == 0:
                continue
            for l in range(4):
                if not (m >> l) & 1:
                    continue
                j = w * P + k + l
                if swept_overlap(
                        sim.px[i], sim.py[i], sim.pheading[i], sim.x[i], sim.y[i], sim.heading[i],
                        sim.hcos[i], sim.hsin[i], 0.5 * sim.length[i], 0.5 * sim.width[i],
                        sim.ped_px[j], sim.ped_py[j], 0.0, sim.ped_x[j], sim.ped_y[j], 0.0,
                        sim.ped_cos[j], sim.ped_sin[j], 0.5 * sim.ped_len[j], 0.5 * sim.ped_wid[j],
                        prm.max_substeps):
                    sim.events[i] |= EV_PED


def collision_scratch(int A, int S, int P):
    """Scratch floats per world that the collision pre-test writes (body_soa: x, y and radius
    of pad4(A) agents, pad4(S) statics and pad4(P) pedestrians)."""
    return 3 * (pad4(A) + pad4(S) + pad4(P))


cdef void body_soa(Sim* sim, int w, float* ax, int nA, float* sx, int nS, float* qx,
                   int nP) noexcept nogil:
    """Struct-of-arrays copy of the bodies of world `w` for the pre-test: for agents (nA
    slots, padded to a multiple of 4), statics (nS) and pedestrians (nP) three arrays each,
    x, y [m] and swept radius (bounding radius + distance moved this step) [m], laid out as
    x[0:n], y[n:2n], r[2n:3n]. Bodies that take no part (empty slots, ended agents not kept,
    vanished pedestrians, padding) get x = NaN. The scratch holds 3 (nA + nS + nP) floats
    (`collision_scratch`)."""
    cdef float nan = NAN
    cdef int a, k, i, A = sim.A, S = sim.S, P = sim.P
    cdef float dx, dy
    for a in range(nA):
        ax[a] = nan
        if a < A:
            i = w * A + a
            if sim.active[i] or sim.obstacle[i]:
                dx = sim.x[i] - sim.px[i]
                dy = sim.y[i] - sim.py[i]
                ax[a] = sim.x[i]
                ax[nA + a] = sim.y[i]
                ax[2 * nA + a] = box_radius(0.5 * sim.length[i], 0.5 * sim.width[i]) + sqrt(dx * dx + dy * dy)
    for k in range(nS):
        sx[k] = nan
        if k < S:
            i = w * S + k
            if sim.st_valid[i]:
                sx[k] = sim.st_x[i]
                sx[nS + k] = sim.st_y[i]
                sx[2 * nS + k] = box_radius(0.5 * sim.st_len[i], 0.5 * sim.st_wid[i])
    for k in range(nP):
        qx[k] = nan
        if k < P:
            i = w * P + k
            if sim.ped_valid[i] and sim.ped_here[i]:
                dx = sim.ped_x[i] - sim.ped_px[i]
                dy = sim.ped_y[i] - sim.ped_py[i]
                qx[k] = sim.ped_x[i]
                qx[nP + k] = sim.ped_y[i]
                qx[2 * nP + k] = box_radius(0.5 * sim.ped_len[i], 0.5 * sim.ped_wid[i]) + sqrt(dx * dx + dy * dy)
