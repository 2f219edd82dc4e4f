# cython: language_level=3
"""Vehicle dynamics (paper section 2.6) as physics-model components.

Every model is a function of the ABI's type `sd_physics_fn` (selfplaydrive_abi.h): it advances
the active agent slots of one world from their actions and writes only the vehicle state it
owns. The world step calls the selected model through a function pointer once per world inside
its parallel loop (`physics_world` below); the models of this module are exported in
`__pyx_capi__` and registered by selfplaydrive/physics/models.py, and a user's numba cfunc or
Cython function is called the same way.

Bicycle geometry (plain, friction, jerk-limited): the box centre is the reference point with
the axles symmetric about it (l_r = l_f = wheelbase/2), so the slip angle is
beta = atan(tan(delta) / 2) and the centre follows a path of curvature kappa = sin(beta) / l_r.
The friction model scales the requested longitudinal acceleration and the lateral acceleration
v^2 kappa by the same factor mu g / |a| when |a| > mu g, so a car entering a turn too fast
follows a larger radius (understeer). Speeds are clamped to [0, max_speed] (no reversing).
Integration: semi-implicit Euler, position with the new speed.
"""

from libc.math cimport sqrt, tanf, sinf, cosf, fabs
from libc.string cimport memcpy, memset
from libc.stdint cimport int32_t, uintptr_t
from selfplaydrive._sim.common cimport Sim, Params, H_FRICTION, H_ACCEL_GAIN, H_STEER_GAIN
from selfplaydrive._sim.geometry cimport wrap_angle

# argument layouts of the built-in models (physics/models.py builds them)
BICYCLE_ARGS = ("wheelbase_ratio", "max_speed", "gravity")
JERK_ARGS = ("wheelbase_ratio", "max_speed", "gravity", "friction", "max_accel", "max_steer")
DELTA_ARGS = ("max_speed",)
JERK_STATE = ("accel", "steer")


def model_addresses():
    """{name: address} of the built-in physics components (`sd_physics_fn`)."""
    return {
        "bicycle": <uintptr_t>phys_bicycle, "friction": <uintptr_t>phys_friction,
        "jerk": <uintptr_t>phys_jerk, "delta": <uintptr_t>phys_delta,
    }


cdef void physics_world(Sim* sim, const Params* prm, const PhysSlot* slot, int w) noexcept nogil:
    """Advance world `w` one step `prm.dt` with the selected model (`slot.fn`; NULL: a Python
    model already moved the vehicles and set px, py, pheading, a_long, a_lat and dist)."""
    cdef int a, i, A = sim.A
    cdef long base = <long>w * A
    cdef double dist
    cdef float dt = prm.dt
    cdef float* state = NULL
    memset(&sim.events[base], 0, A)  # fresh event bits
    if slot.fn == NULL:
        return
    # what every model would otherwise repeat: the sweep start of the collision stage and no
    # acceleration for a slot the model leaves alone (block copies: the world's slots are
    # contiguous; +0.0 as the paper build stored)
    memcpy(&sim.px[base], &sim.x[base], A * sizeof(float))
    memcpy(&sim.py[base], &sim.y[base], A * sizeof(float))
    memcpy(&sim.pheading[base], &sim.heading[base], A * sizeof(float))
    memset(&sim.a_long[base], 0, A * sizeof(float))
    memset(&sim.a_lat[base], 0, A * sizeof(float))
    if sim.phys_dim > 0:
        state = &sim.phys_state[<long>w * A * sim.phys_dim]
    slot.fn(sim, prm, slot.args, w, state)
    # the world's distance is accumulated locally, in agent order, and stored once: the same
    # sum, and no store per agent to a line the world next door may be writing (threads)
    dist = sim.dist[w]
    for a in range(A):
        i = w * A + a
        if sim.active[i]:
            dist += sim.speed[i] * dt
    sim.dist[w] = dist


# the paper's models ---------------------------------------------------------------------------
cdef void phys_bicycle(Sim* sim, const Params* prm, const float* args, int32_t w,
                       float* state) noexcept nogil:
    """Kinematic bicycle, no friction limit. args: wheelbase_ratio, max_speed, gravity."""
    bicycle_world(sim, prm, args, w, False)


cdef void phys_friction(Sim* sim, const Params* prm, const float* args, int32_t w,
                        float* state) noexcept nogil:
    """Kinematic bicycle with the per-vehicle friction limit mu g (the default)."""
    bicycle_world(sim, prm, args, w, True)


cdef inline void bicycle_world(Sim* sim, const Params* prm, const float* args, int32_t w,
                               bint friction) noexcept nogil:
    cdef int a, i, D = sim.act_dim
    cdef float acc, steer
    for a in range(sim.A):
        i = w * sim.A + a
        if not sim.active[i]:
            continue
        if prm.discrete:
            acc = prm.accel_table[sim.act_i[D * i]]
            steer = prm.steer_table[sim.act_i[D * i + 1]]
        else:
            acc = sim.act_f[D * i]
            steer = sim.act_f[D * i + 1]
        # hidden gains multiply every action (section 2.6)
        acc = acc * sim.hidden[3 * i + H_ACCEL_GAIN]
        steer = steer * sim.hidden[3 * i + H_STEER_GAIN]
        advance(sim, i, acc, steer, prm.dt, args[0], args[1], args[2], friction)


cdef inline void advance(Sim* sim, int i, float acc, float steer, float dt, float wb_ratio,
                         float max_speed, float gravity, bint friction) noexcept nogil:
    """Move agent i one step with acceleration `acc` [m/s^2] and steering `steer` [rad] (gains
    applied). The arithmetic is the paper build's, operation for operation (pinned digests)."""
    cdef float v0, v1, vreq, lw, tb, norm, kappa, alat, scale, sb, cb, th, mu_g
    cdef float ch, sh
    v0 = sim.speed[i]
    lw = wb_ratio * sim.length[i]
    tb = <float>0.5 * tanf(steer)                       # tan(beta) with l_r / L = 1/2
    sb = tb / sqrt(1.0 + tb * tb)               # sin(beta) without atan
    kappa = 2.0 * sb / lw                       # path curvature of the centre [1/m]
    if friction:
        vreq = clampf(v0 + acc * dt, 0.0, max_speed)
        alat = vreq * vreq * kappa
        norm = sqrt(acc * acc + alat * alat)
        mu_g = sim.hidden[3 * i + H_FRICTION] * gravity
        if norm > mu_g:
            # friction circle: scale both components, the car understeers
            scale = mu_g / norm
            acc = acc * scale
            kappa = kappa * scale
        v1 = clampf(v0 + acc * dt, 0.0, max_speed)
        # braking less than requested ends the step faster: cap the lateral part at the end
        # speed so the realised (a_long, a_lat) stays inside the friction circle
        alat = mu_g * mu_g - acc * acc
        alat = sqrt(alat) if alat > 0.0 else 0.0
        if v1 * v1 * fabs(kappa) > alat:
            kappa = alat / (v1 * v1) if kappa > 0.0 else -alat / (v1 * v1)
        sb = kappa * 0.5 * lw
    v1 = clampf(v0 + acc * dt, 0.0, max_speed)
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


# jerk-limited bicycle (Gigaflow; PufferDrive 3.0) ------------------------------------------------
cdef void phys_jerk(Sim* sim, const Params* prm, const float* args, int32_t w,
                    float* state) noexcept nogil:
    """Bicycle driven by CHANGES of acceleration and steering: the model owns the commanded
    acceleration and steering of every slot (state columns 0, 1; 0 at spawn), adds the action
    (a table value, or the continuous value) and clamps them to +-max_accel, +-max_steer, then
    moves the car as the bicycle (friction limit when args[3] != 0) with the hidden gains
    applied. args: wheelbase_ratio, max_speed, gravity, friction, max_accel [m/s^2],
    max_steer [rad]."""
    cdef int a, i, D = sim.act_dim
    cdef float da, ds, acc, steer
    for a in range(sim.A):
        i = w * sim.A + a
        if not sim.active[i]:
            continue
        if prm.discrete:
            da = prm.accel_table[sim.act_i[D * i]]
            ds = prm.steer_table[sim.act_i[D * i + 1]]
        else:
            da = sim.act_f[D * i]
            ds = sim.act_f[D * i + 1]
        acc = clampf(state[2 * a] + da, -args[4], args[4])
        steer = clampf(state[2 * a + 1] + ds, -args[5], args[5])
        state[2 * a] = acc
        state[2 * a + 1] = steer
        advance(sim, i, acc * sim.hidden[3 * i + H_ACCEL_GAIN], steer * sim.hidden[3 * i + H_STEER_GAIN],
                prm.dt, args[0], args[1], args[2], args[3] != 0.0)


# Waymax-style delta model ----------------------------------------------------------------------
cdef void phys_delta(Sim* sim, const Params* prm, const float* args, int32_t w,
                     float* state) noexcept nogil:
    """The action is the motion itself: (dx, dy) [m] in the agent's frame at the start of the
    step and dyaw [rad] (continuous, bounded by the action space). The new speed is the
    displacement over dt; a displacement faster than args[0] (max_speed) is shortened to it.
    a_long = (v1 - v0) / dt, a_lat = v1 * dyaw / dt (speed times yaw rate). Hidden gains do not
    apply: the model has no actuators (physics/models.py `DeltaModel.inverse` recovers the action
    from two consecutive states)."""
    cdef int a, i, D = sim.act_dim
    cdef float dx, dy, dyaw, ch, sh, d, v0, v1, th, dt = prm.dt
    for a in range(sim.A):
        i = w * sim.A + a
        if not sim.active[i]:
            continue
        dx = sim.act_f[D * i]
        dy = sim.act_f[D * i + 1]
        dyaw = sim.act_f[D * i + 2]
        d = sqrt(dx * dx + dy * dy)
        if d > args[0] * dt:
            dx = dx * (args[0] * dt / d)
            dy = dy * (args[0] * dt / d)
            d = args[0] * dt
        v0 = sim.speed[i]
        v1 = d / dt
        ch = sim.hcos[i]
        sh = sim.hsin[i]
        sim.x[i] = sim.x[i] + (ch * dx - sh * dy)
        sim.y[i] = sim.y[i] + (sh * dx + ch * dy)
        th = wrap_angle(sim.heading[i] + dyaw)
        sim.heading[i] = th
        sim.hcos[i] = cosf(th)
        sim.hsin[i] = sinf(th)
        sim.speed[i] = v1
        sim.a_long[i] = (v1 - v0) / dt
        sim.a_lat[i] = v1 * dyaw / dt


cdef inline float clampf(float v, float lo, float hi) noexcept nogil:
    if v < lo:
        return lo
    if v > hi:
        return hi
    return v
