# cython: language_level=3
"""Reward terms, terminations and truncations (paper section 2.3), and the end-of-step
bookkeeping of a world (final observations, ended agents, episode statistics).

Every reward term is a component of the ABI in selfplaydrive_abi.h (`sd_reward_term_fn`): the
world step calls the selected ones through function pointers, once per world, and sums their
weighted columns. The paper's eight terms below are ordinary components of that contract
(exported in this module's `__pyx_capi__`; selfplaydrive/rewards/components.py registers them);
a user's numba `cfunc` or Cython function is called the same way.
"""

from libc.math cimport cosf, expf, fabs, M_PI
from libc.string cimport memcpy
from libc.stdint cimport int32_t, int64_t, uint8_t, uintptr_t
from selfplaydrive._sim.common cimport (Sim, Params, Atlas, EV_COLLIDE, EV_PED, EV_OFFROAD,
                                        EV_RED, EV_WAYPOINT, EV_COMFORT, C_COLLISION, C_OFFROAD,
                                        C_RED, C_COMFORT, C_CENTER, C_BIAS, C_ALIGN, NUM_COEFFS,
                                        T_WAYPOINT, T_COLLISION, T_OFFROAD, T_RED, T_COMFORT,
                                        T_CENTER, T_ALIGN, T_VELOCITY,
                                        MAX_TERMS, NUM_STATS, S_COLLIDE, S_PED, S_OFFROAD, S_RED,
                                        S_WAYPOINT, S_COMFORT, S_TERMINATED, S_TRUNCATED)

# Names of the paper's terms (rewards/registry.py TERM_NAMES) and their functions.
PAPER_TERMS = ("waypoint", "collision", "offroad", "red_light", "comfort", "center", "align",
               "velocity")


def paper_term_addresses():
    """{name: address} of the paper's eight reward components (section 2.3)."""
    return {
        "waypoint": <uintptr_t>term_waypoint, "collision": <uintptr_t>term_collision,
        "offroad": <uintptr_t>term_offroad, "red_light": <uintptr_t>term_red_light,
        "comfort": <uintptr_t>term_comfort, "center": <uintptr_t>term_center,
        "align": <uintptr_t>term_align, "velocity": <uintptr_t>term_velocity,
    }


def paper_group_address():
    """Address of `term_paper`: the eight terms in one pass, writing 8 consecutive columns."""
    return <uintptr_t>term_paper


def abi_sizes():
    """sizeof of the ABI's structs in this build (checked against the numba view in tests)."""
    return {"sim": sizeof(Sim), "params": sizeof(Params), "atlas": sizeof(Atlas)}


def max_terms():
    """Most reward columns one env may select (SD_MAX_TERMS)."""
    return MAX_TERMS


cdef void reward_world(Sim* sim, const Atlas* atlas, const Params* prm, const TermSlot* slots,
                       int w) noexcept nogil:
    """Per-term rewards, their sum, terminations and truncations of every slot of world `w`.
    Each selected component writes its column(s) of the world's rows (sim.num_terms columns);
    the weighted columns are then summed in column order (section 2.3: the reward is a weighted
    sum of named terms). Columns filled in Python (`native` 0) are zeroed here and added after
    the step. The world's per-term sums and event counts are accumulated in locals (in agent
    order, so the same sums) and stored once: no store per agent to lines shared with the
    world next door when threads step neighbouring worlds."""
    cdef int a, i, k, M = sim.num_terms
    cdef int64_t row
    cdef float t
    cdef bint plain = True  # every column native with weight 1 (the paper's configuration)
    cdef bint time_up = sim.step[w] >= sim.max_steps[w]
    cdef double sums[MAX_TERMS]
    cdef int64_t counts[NUM_STATS]
    cdef float* rows = &sim.terms[<int64_t>w * sim.A * M]
    for k in range(M):
        sums[k] = sim.term_sum[w * M + k]
        plain = plain and slots[k].native and slots[k].weight == 1.0
        if slots[k].fn != NULL:
            slots[k].fn(sim, prm, atlas, slots[k].args, w, rows + k, M)
    for k in range(NUM_STATS):
        counts[k] = sim.ev_count[w * NUM_STATS + k]
    for a in range(sim.A):
        i = w * sim.A + a
        row = <int64_t>i * M
        if not sim.active[i]:
            for k in range(M):
                sim.terms[row + k] = 0.0
            sim.reward[i] = 0.0
            sim.term[i] = 0
            sim.trunc[i] = 0
            continue
        sim.reward[i] = 0.0
        if plain:
            for k in range(M):
                sim.reward[i] += sim.terms[row + k]
                sums[k] += sim.terms[row + k]
        else:
            for k in range(M):
                if not slots[k].native:
                    sim.terms[row + k] = 0.0
                    continue
                t = sim.terms[row + k] * slots[k].weight
                sim.terms[row + k] = t
                sim.reward[i] += t
                sums[k] += t
        sim.term[i] = terminates(sim, prm, i)
        # reaching the time limit is a truncation, reported apart from termination (section 2)
        sim.trunc[i] = time_up and not sim.term[i]
        count_events(sim, counts, i)
    for k in range(M):
        sim.term_sum[w * M + k] = sums[k]
    for k in range(NUM_STATS):
        sim.ev_count[w * NUM_STATS + k] = counts[k]


cdef void term_paper(const Sim* sim, const Params* prm, const Atlas* atlas, const float* args,
                     int32_t w, float* out, int32_t stride) noexcept nogil:
    """The paper's eight terms in one pass over the world's agents, written to the 8
    consecutive columns out[a * stride + T_WAYPOINT .. T_VELOCITY]: what the step calls when all
    eight are selected in their order (rewards/components.py `LinearReward.plan`), instead of
    eight passes. Same values as the eight single-term components below, bit for bit."""
    cdef int a, A = sim.A
    for a in range(A):
        if sim.active[<int64_t>w * A + a]:
            agent_terms(sim, prm, w * A + a, out + <int64_t>a * stride)


cdef inline void agent_terms(const Sim* sim, const Params* prm, int i, float* t) noexcept nogil:
    """The eight terms of section 2.3 for agent i, written to t[0:8]."""
    cdef unsigned char ev = sim.events[i]
    cdef const float* cf = &sim.coeffs[i * NUM_COEFFS]
    cdef float v = sim.speed[i], al, ca, dev
    cdef double gain = prm.collision_speed_gain  # double: the product rounds as the paper's 0.1 did
    t[T_WAYPOINT] = prm.waypoint_reward if ev & EV_WAYPOINT else 0.0
    t[T_COLLISION] = -cf[C_COLLISION] * (1.0 + gain * v) if ev & (EV_COLLIDE | EV_PED) else 0.0
    t[T_OFFROAD] = -cf[C_OFFROAD] * (1.0 + gain * v) if ev & EV_OFFROAD else 0.0
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
        t[T_CENTER] = cf[C_CENTER] * (-dev + prm.center_bonus / expf(dev - prm.center_bonus_offset))
    t[T_ALIGN] = cf[C_ALIGN] * (min(ca, 0.0) + prm.align_bonus * (1.0 - fabs(al) / (0.5 * M_PI)))
    if v >= prm.velocity_min:
        t[T_VELOCITY] = prm.velocity_reward * max(ca, 0.0)


# The paper's eight terms (section 2.3), one component each. They skip inactive slots (the
# step zeroes those rows) and read only the agent's own state. The world's arrays are taken
# into local pointers first: `out` may alias anything as far as the compiler knows, so fields
# read through `sim` inside the loop would be loaded again after every store.

cdef void term_waypoint(const Sim* sim, const Params* prm, const Atlas* atlas, const float* args,
                        int32_t w, float* out, int32_t stride) noexcept nogil:
    """R = waypoint_reward (0.25) when the current waypoint was reached this step."""
    cdef int a, A = sim.A
    cdef const uint8_t* active = sim.active + <int64_t>w * A
    cdef const uint8_t* ev = sim.events + <int64_t>w * A
    cdef float r = prm.waypoint_reward
    for a in range(A):
        if active[a]:
            out[<int64_t>a * stride] = r if ev[a] & EV_WAYPOINT else 0.0


cdef void term_collision(const Sim* sim, const Params* prm, const Atlas* atlas, const float* args,
                         int32_t w, float* out, int32_t stride) noexcept nogil:
    """R = -C_collision (1 + g v) when the box overlaps a vehicle or a pedestrian (g =
    collision_speed_gain, 0.1)."""
    cdef int a, A = sim.A
    cdef const uint8_t* active = sim.active + <int64_t>w * A
    cdef const uint8_t* ev = sim.events + <int64_t>w * A
    cdef const float* speed = sim.speed + <int64_t>w * A
    cdef const float* cf = sim.coeffs + <int64_t>w * A * NUM_COEFFS + C_COLLISION
    cdef float v
    cdef double gain = prm.collision_speed_gain
    for a in range(A):
        if active[a]:
            v = speed[a]
            out[<int64_t>a * stride] = (-cf[a * NUM_COEFFS] * (1.0 + gain * v)
                                        if ev[a] & (EV_COLLIDE | EV_PED) else 0.0)


cdef void term_offroad(const Sim* sim, const Params* prm, const Atlas* atlas, const float* args,
                       int32_t w, float* out, int32_t stride) noexcept nogil:
    """R = -C_offroad (1 + g v) when the box touches a road edge (g = collision_speed_gain)."""
    cdef int a, A = sim.A
    cdef const uint8_t* active = sim.active + <int64_t>w * A
    cdef const uint8_t* ev = sim.events + <int64_t>w * A
    cdef const float* speed = sim.speed + <int64_t>w * A
    cdef const float* cf = sim.coeffs + <int64_t>w * A * NUM_COEFFS + C_OFFROAD
    cdef float v
    cdef double gain = prm.collision_speed_gain
    for a in range(A):
        if active[a]:
            v = speed[a]
            out[<int64_t>a * stride] = (-cf[a * NUM_COEFFS] * (1.0 + gain * v)
                                        if ev[a] & EV_OFFROAD else 0.0)


cdef inline void event_penalty(const Sim* sim, int32_t w, float* out, int32_t stride, int bit,
                               int coeff) noexcept nogil:
    """R = -C[coeff] in the steps where event `bit` happened (red light, comfort)."""
    cdef int a, A = sim.A
    cdef const uint8_t* active = sim.active + <int64_t>w * A
    cdef const uint8_t* ev = sim.events + <int64_t>w * A
    cdef const float* cf = sim.coeffs + <int64_t>w * A * NUM_COEFFS + coeff
    for a in range(A):
        if active[a]:
            out[<int64_t>a * stride] = -cf[a * NUM_COEFFS] if ev[a] & bit else 0.0


cdef void term_red_light(const Sim* sim, const Params* prm, const Atlas* atlas, const float* args,
                         int32_t w, float* out, int32_t stride) noexcept nogil:
    """R = -C_red when the box touches (or the centre crossed) a red light's line."""
    event_penalty(sim, w, out, stride, EV_RED, C_RED)


cdef void term_comfort(const Sim* sim, const Params* prm, const Atlas* atlas, const float* args,
                       int32_t w, float* out, int32_t stride) noexcept nogil:
    """R = -C_comfort when |a_long| or |a_lat| exceeds the comfort limit (3 m/s^2)."""
    event_penalty(sim, w, out, stride, EV_COMFORT, C_COMFORT)


cdef void term_center(const Sim* sim, const Params* prm, const Atlas* atlas, const float* args,
                      int32_t w, float* out, int32_t stride) noexcept nogil:
    """R = C_center (-|B - s| + 0.05 / exp(|B - s| - 0.5)) when |alpha| < 60 deg (0.05:
    center_bonus, 0.5: center_bonus_offset, 60 deg: center_max_angle)."""
    cdef int a, A = sim.A
    cdef const uint8_t* active = sim.active + <int64_t>w * A
    cdef const uint8_t* valid = sim.lane_valid + <int64_t>w * A
    cdef const float* alpha = sim.lane_alpha + <int64_t>w * A
    cdef const float* lane_s = sim.lane_s + <int64_t>w * A
    cdef const float* cf = sim.coeffs + <int64_t>w * A * NUM_COEFFS
    cdef float max_angle = prm.center_max_angle, dev, t, off = prm.center_bonus_offset
    cdef double bonus = prm.center_bonus
    for a in range(A):
        if not active[a]:
            continue
        t = 0.0  # no centerline within lane_radius: the lane terms are zero
        if valid[a] and fabs(alpha[a]) < max_angle:
            dev = fabs(cf[a * NUM_COEFFS + C_BIAS] - lane_s[a])
            t = cf[a * NUM_COEFFS + C_CENTER] * (-dev + bonus / expf(dev - off))
        out[<int64_t>a * stride] = t


cdef void term_align(const Sim* sim, const Params* prm, const Atlas* atlas, const float* args,
                     int32_t w, float* out, int32_t stride) noexcept nogil:
    """R = C_align (min(cos alpha, 0) + 0.0025 (1 - |alpha| / (pi / 2))) when a lane is associated
    (0.0025: align_bonus)."""
    cdef int a, A = sim.A
    cdef const uint8_t* active = sim.active + <int64_t>w * A
    cdef const uint8_t* valid = sim.lane_valid + <int64_t>w * A
    cdef const float* alpha = sim.lane_alpha + <int64_t>w * A
    cdef const float* cf = sim.coeffs + <int64_t>w * A * NUM_COEFFS + C_ALIGN
    cdef float al, ca, t
    cdef double bonus = prm.align_bonus
    for a in range(A):
        if not active[a]:
            continue
        t = 0.0
        if valid[a]:
            al = alpha[a]
            ca = cosf(al)
            t = cf[a * NUM_COEFFS] * (min(ca, 0.0) + bonus * (1.0 - fabs(al) / (0.5 * M_PI)))
        out[<int64_t>a * stride] = t


cdef void term_velocity(const Sim* sim, const Params* prm, const Atlas* atlas, const float* args,
                        int32_t w, float* out, int32_t stride) noexcept nogil:
    """R = 2.5e-4 max(cos alpha, 0) when v >= 2.5 m/s and a lane is associated."""
    cdef int a, A = sim.A
    cdef const uint8_t* active = sim.active + <int64_t>w * A
    cdef const uint8_t* valid = sim.lane_valid + <int64_t>w * A
    cdef const float* alpha = sim.lane_alpha + <int64_t>w * A
    cdef const float* speed = sim.speed + <int64_t>w * A
    cdef float vmin = prm.velocity_min, r = prm.velocity_reward, t
    for a in range(A):
        if not active[a]:
            continue
        t = 0.0
        if valid[a] and speed[a] >= vmin:
            t = r * max(cosf(alpha[a]), 0.0)
        out[<int64_t>a * stride] = t


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
