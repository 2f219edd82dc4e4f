# cython: language_level=3
"""Reward terms, terminations and truncations (paper section 2.3), and the end-of-step
bookkeeping of a world (final observations, ended agents, episode statistics)."""

from libc.math cimport cosf, expf, fabs, M_PI
from libc.string cimport memcpy
from libc.stdint cimport int64_t
from selfplaydrive._sim.common cimport (Sim, Params, EV_COLLIDE, EV_PED, EV_OFFROAD, EV_RED,
                                        EV_WAYPOINT, EV_COMFORT, T_WAYPOINT, T_COLLISION,
                                        T_OFFROAD, T_RED, T_COMFORT, T_CENTER, T_ALIGN,
                                        T_VELOCITY, NUM_TERMS, C_COLLISION, C_OFFROAD, C_RED,
                                        C_COMFORT, C_CENTER, C_BIAS, C_ALIGN, NUM_STATS, S_COLLIDE,
                                        S_PED, S_OFFROAD, S_RED, S_WAYPOINT, S_COMFORT,
                                        S_TERMINATED, S_TRUNCATED)


cdef void reward_world(Sim* sim, const Params* prm, int w) noexcept nogil:
    """Per-term rewards, their sum, terminations and truncations of every slot of world `w`.
    The world's per-term sums and event counts are accumulated in locals (in agent order, so
    the same sums) and stored once: no store per agent to lines shared with the world next
    door when threads step neighbouring worlds."""
    cdef int a, i, k
    cdef bint time_up = sim.step[w] >= sim.max_steps[w]
    cdef double sums[NUM_TERMS]
    cdef int64_t counts[NUM_STATS]
    for k in range(NUM_TERMS):
        sums[k] = sim.term_sum[w * NUM_TERMS + k]
    for k in range(NUM_STATS):
        counts[k] = sim.ev_count[w * NUM_STATS + k]
    for a in range(sim.A):
        i = w * sim.A + a
        if not sim.active[i]:
            for k in range(NUM_TERMS):
                sim.terms[i * NUM_TERMS + k] = 0.0
            sim.reward[i] = 0.0
            sim.term[i] = 0
            sim.trunc[i] = 0
            continue
        agent_terms(sim, prm, i, &sim.terms[i * NUM_TERMS])
        sim.reward[i] = 0.0
        for k in range(NUM_TERMS):
            sim.reward[i] += sim.terms[i * NUM_TERMS + k]
            sums[k] += sim.terms[i * NUM_TERMS + k]
        sim.term[i] = terminates(sim, prm, i)
        # reaching the time limit is a truncation, reported apart from termination (section 2)
        sim.trunc[i] = time_up and not sim.term[i]
        count_events(sim, counts, i)
    for k in range(NUM_TERMS):
        sim.term_sum[w * NUM_TERMS + k] = sums[k]
    for k in range(NUM_STATS):
        sim.ev_count[w * NUM_STATS + k] = counts[k]


cdef void agent_terms(Sim* sim, const Params* prm, int i, float* t) noexcept nogil:
    """The eight terms of section 2.3 for agent i, written to t[0:8]."""
    cdef unsigned char ev = sim.events[i]
    cdef const float* cf = &sim.coeffs[i * 8]
    cdef float v = sim.speed[i], al, ca, dev
    t[T_WAYPOINT] = prm.waypoint_reward if ev & EV_WAYPOINT else 0.0
    t[T_COLLISION] = -cf[C_COLLISION] * (1.0 + 0.1 * v) if ev & (EV_COLLIDE | EV_PED) else 0.0
    t[T_OFFROAD] = -cf[C_OFFROAD] * (1.0 + 0.1 * v) if ev & EV_OFFROAD else 0.0
    t[T_RED] = -cf[C_RED] if ev & EV_RED else 0.0
    t[T_COMFORT] = -cf[C_COMFORT] if ev & EV_COMFORT else 0.0
    t[T_CENTER] = 0.0
    t[T_ALIGN] = 0.0
    t[T_VELOCITY] = 0.0
    if not sim.lane_valid[i]:
        return  # no centerline within lane_radius: the lane terms are zero
    al = sim.lane_alpha[i]
    ca = cosf(al)
    if fabs(al) < prm.center_max_angle:
        dev = fabs(cf[C_BIAS] - sim.lane_s[i])
        t[T_CENTER] = cf[C_CENTER] * (-dev + 0.05 / expf(dev - <float>0.5))
    t[T_ALIGN] = cf[C_ALIGN] * (min(ca, 0.0) + 0.0025 * (1.0 - fabs(al) / (0.5 * M_PI)))
    if v >= prm.velocity_min:
        t[T_VELOCITY] = prm.velocity_reward * max(ca, 0.0)


cdef inline bint terminates(Sim* sim, const Params* prm, int i) noexcept nogil:
    """A collision ends the agent when C_collision >= 0.5, road-edge contact when C_offroad >= 0.5."""
    cdef unsigned char ev = sim.events[i]
    if ev & (EV_COLLIDE | EV_PED) and sim.coeffs[i * 8 + C_COLLISION] >= prm.terminate_threshold:
        return True
    if ev & EV_OFFROAD and sim.coeffs[i * 8 + C_OFFROAD] >= prm.terminate_threshold:
        return True
    return False


cdef inline void count_events(Sim* sim, int64_t* c, int i) noexcept nogil:
    cdef unsigned char ev = sim.events[i]
    c[S_COLLIDE] += (ev & EV_COLLIDE) != 0
    c[S_PED] += (ev & EV_PED) != 0
    c[S_OFFROAD] += (ev & EV_OFFROAD) != 0
    c[S_RED] += (ev & EV_RED) != 0
    c[S_WAYPOINT] += (ev & EV_WAYPOINT) != 0
    c[S_COMFORT] += (ev & EV_COMFORT) != 0
    c[S_TERMINATED] += sim.term[i]
    c[S_TRUNCATED] += sim.trunc[i]
    sim.ever[i] |= ev


cdef void finalize_world(Sim* sim, const Params* prm, int w) noexcept nogil:
    """Keep final observations of agents that ended, retire them (removed or left as
    obstacles) and mark the world done when its time is up or no agent is left."""
    cdef int a, i, left = 0
    for a in range(sim.A):
        i = w * sim.A + a
        if not sim.active[i]:
            continue
        if sim.term[i] or sim.trunc[i]:
            memcpy(&sim.final_obs[<int64_t>i * sim.obs_dim], &sim.obs[<int64_t>i * sim.obs_dim],
                   sim.obs_dim * sizeof(float))
            sim.active[i] = 0
            if sim.term[i] and prm.obstacle_mode:
                sim.obstacle[i] = 1
                sim.speed[i] = 0.0
        else:
            left += 1
    sim.done[w] = sim.step[w] >= sim.max_steps[w] or left == 0
