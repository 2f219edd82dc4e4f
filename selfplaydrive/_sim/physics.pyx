# cython: language_level=3
"""Vehicle dynamics (paper section 2.6): kinematic bicycle model with an optional friction
limit and hidden per-vehicle action gains.

Reference point: the box centre, with the axles symmetric about it (l_r = l_f = wheelbase/2),
so the slip angle is beta = atan(tan(delta) / 2) and the centre follows a path of curvature
kappa = sin(beta) / l_r. The friction model scales the requested longitudinal acceleration
and the lateral acceleration v^2 kappa by the same factor mu g / |a| when |a| > mu g, so a car
entering a turn too fast follows a larger radius (understeer). Speeds are clamped to
[0, max_speed] (no reversing). Integration: semi-implicit Euler, position with the new speed.
"""

from libc.math cimport sqrt, tanf, sinf, cosf, fabs
from selfplaydrive._sim.common cimport (Sim, Params, PHYS_FRICTION, PHYS_EXTERNAL, H_FRICTION,
                                        H_ACCEL_GAIN, H_STEER_GAIN)
from selfplaydrive._sim.geometry cimport wrap_angle


cdef void physics_world(Sim* sim, const Params* prm, int w) noexcept nogil:
    """Advance every active agent of world `w` by one step `prm.dt` from its action."""
    cdef int a, i
    cdef double dist = sim.dist[w]
    if prm.physics == PHYS_EXTERNAL:
        # a Python model already moved the vehicles and set px, py, pheading, a_long, a_lat
        for a in range(sim.A):
            sim.events[w * sim.A + a] = 0
        return
    for a in range(sim.A):
        i = w * sim.A + a
        sim.px[i] = sim.x[i]
        sim.py[i] = sim.y[i]
        sim.pheading[i] = sim.heading[i]
        sim.events[i] = 0
        if sim.active[i]:
            dist += step_vehicle(sim, prm, i)
        else:
            sim.a_long[i] = 0.0
            sim.a_lat[i] = 0.0
    # the world's distance is accumulated locally, in agent order, and stored once: the same
    # sum, and no store per agent to a line the world next door may be writing (threads)
    sim.dist[w] = dist


cdef inline double step_vehicle(Sim* sim, const Params* prm, int i) noexcept nogil:
    """Advance agent i one step; returns the distance it drove [m] (v1 dt)."""
    cdef float acc, steer, v0, v1, vreq, lw, tb, norm, kappa, alat, scale, sb, cb, th, mu_g
    cdef float ch, sh, dt = prm.dt
    if prm.discrete:
        acc = prm.accel_table[sim.act_i[2 * i]]
        steer = prm.steer_table[sim.act_i[2 * i + 1]]
    else:
        acc = sim.act_f[2 * i]
        steer = sim.act_f[2 * i + 1]
    # hidden gains multiply every action (section 2.6)
    acc = acc * sim.hidden[3 * i + H_ACCEL_GAIN]
    steer = steer * sim.hidden[3 * i + H_STEER_GAIN]
    v0 = sim.speed[i]
    lw = prm.wheelbase_ratio * sim.length[i]
    tb = <float>0.5 * tanf(steer)                       # tan(beta) with l_r / L = 1/2
    sb = tb / sqrt(1.0 + tb * tb)               # sin(beta) without atan
    kappa = 2.0 * sb / lw                       # path curvature of the centre [1/m]
    if prm.physics == PHYS_FRICTION:
        vreq = clampf(v0 + acc * dt, 0.0, prm.max_speed)
        alat = vreq * vreq * kappa
        norm = sqrt(acc * acc + alat * alat)
        mu_g = sim.hidden[3 * i + H_FRICTION] * prm.gravity
        if norm > mu_g:
            # friction circle: scale both components, the car understeers
            scale = mu_g / norm
            acc = acc * scale
            kappa = kappa * scale
        v1 = clampf(v0 + acc * dt, 0.0, prm.max_speed)
        # braking less than requested ends the step faster: cap the lateral part at the end
        # speed so the realised (a_long, a_lat) stays inside the friction circle
        alat = mu_g * mu_g - acc * acc
        alat = sqrt(alat) if alat > 0.0 else 0.0
        if v1 * v1 * fabs(kappa) > alat:
            kappa = alat / (v1 * v1) if kappa > 0.0 else -alat / (v1 * v1)
        sb = kappa * 0.5 * lw
    v1 = clampf(v0 + acc * dt, 0.0, prm.max_speed)
    cb = sqrt(1.0 - sb * sb)
    ch = sim.hcos[i]
    sh = sim.hsin[i]
    # direction of travel = heading + beta
    sim.x[i] = sim.x[i] + v1 * (ch * cb - sh * sb) * dt
    sim.y[i] = sim.y[i] + v1 * (sh * cb + ch * sb) * dt
    th = wrap_angle(sim.heading[i] + v1 * kappa * dt)
    sim.heading[i] = th
    sim.hcos[i] = cosf(th)
    sim.hsin[i] = sinf(th)
    sim.speed[i] = v1
    sim.a_long[i] = (v1 - v0) / dt
    sim.a_lat[i] = v1 * v1 * kappa
    return v1 * dt


cdef inline float clampf(float v, float lo, float hi) noexcept nogil:
    if v < lo:
        return lo
    if v > hi:
        return hi
    return v
