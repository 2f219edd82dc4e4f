# cython: language_level=3
"""Shaping terms for learning on a small budget (issue #16 item 2), off by default: the paper's
reward (section 2.3) stays as it is and these are extra columns selected with
``+reward.terms.conflict=W``. They are components of the reward ABI (selfplaydrive_abi.h,
`sd_reward_term_fn`) like the paper's terms; rewards/shaping.py registers them and
selfplaydrive/testing/shaping_terms.py holds the NumPy reference.

Why: in the main job most agents end in collisions with other agents at junctions (docs/training.md
"Tuning the main job"); the collision term pays only at contact, after the last moment to brake.
`conflict` pays, every step, for being on a collision course, so the signal comes while a
different action still helps.
"""

from libc.stdint cimport int32_t, int64_t, uint8_t, uintptr_t
from selfplaydrive._sim.common cimport Sim, Params, Atlas


def shaping_term_addresses():
    """{name: address} of the shaping components."""
    return {"conflict": <uintptr_t>term_conflict}


cdef inline float approach(float px, float py, float vx, float vy, float horizon,
                           float reach) noexcept nogil:
    """1 - t / horizon when a body at relative position (px, py) [m] moving at relative velocity
    (vx, vy) [m/s] comes within `reach` [m] of the origin at its closest approach at time t in
    [0, horizon] s (constant velocities), else 0."""
    cdef float vv = vx * vx + vy * vy, t = 0.0, dx, dy
    if vv > 1e-6:
        t = -(px * vx + py * vy) / vv
        if t < 0.0:
            t = 0.0
        elif t > horizon:
            t = horizon
    dx = px + vx * t
    dy = py + vy * t
    if dx * dx + dy * dy < reach * reach:
        return 1.0 - t / horizon
    return 0.0


cdef void term_conflict(const Sim* sim, const Params* prm, const Atlas* atlas, const float* args,
                        int32_t w, float* out, int32_t stride) noexcept nogil:
    """R = -max_j (1 - t_j / T) over the bodies j (other agents, agents kept as obstacles,
    static vehicles, present pedestrians) whose closest approach to the agent within T = args[0]
    s, both keeping their velocities, is nearer than half the two widths plus args[1] m; t_j is
    the time of that approach. Widths, not lengths: cars side by side in adjacent lanes are no
    conflict, a car closing on another along its lane is. 0 when there is none."""
    cdef int a, b, A = sim.A, S = sim.S, P = sim.P
    cdef int64_t i, j
    cdef float horizon = args[0], margin = args[1]
    cdef float worst, c, xa, ya, vxa, vya, hwa, vxb, vyb
    for a in range(A):
        i = <int64_t>w * A + a
        if not sim.active[i]:
            continue
        worst = 0.0
        xa = sim.x[i]
        ya = sim.y[i]
        vxa = sim.speed[i] * sim.hcos[i]
        vya = sim.speed[i] * sim.hsin[i]
        hwa = 0.5 * sim.width[i] + margin
        for b in range(A):
            j = <int64_t>w * A + b
            if b == a or not (sim.active[j] or sim.obstacle[j]):
                continue
            vxb = sim.speed[j] * sim.hcos[j] if sim.active[j] else 0.0
            vyb = sim.speed[j] * sim.hsin[j] if sim.active[j] else 0.0
            c = approach(sim.x[j] - xa, sim.y[j] - ya, vxb - vxa, vyb - vya, horizon,
                         hwa + 0.5 * sim.width[j])
            if c > worst:
                worst = c
        for b in range(S):
            j = <int64_t>w * S + b
            if sim.st_valid[j]:
                c = approach(sim.st_x[j] - xa, sim.st_y[j] - ya, -vxa, -vya, horizon,
                             hwa + 0.5 * sim.st_wid[j])
                if c > worst:
                    worst = c
        for b in range(P):
            j = <int64_t>w * P + b
            if sim.ped_valid[j] and sim.ped_here[j]:
                c = approach(sim.ped_x[j] - xa, sim.ped_y[j] - ya, sim.ped_vx[j] - vxa,
                             sim.ped_vy[j] - vya, horizon, hwa + 0.5 * sim.ped_wid[j])
                if c > worst:
                    worst = c
        out[<int64_t>a * stride] = -worst
