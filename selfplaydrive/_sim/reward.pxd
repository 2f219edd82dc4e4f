# cython: language_level=3
from libc.stdint cimport int32_t
from selfplaydrive._sim.common cimport Sim, Params, Atlas, reward_term_fn


ctypedef struct TermSlot:
    # One column of the per-term reward buffer (internal to the step, not part of the ABI).
    reward_term_fn fn        # the component writing this column (and, for a group such as
                             # term_paper, the next ones); NULL: no call for this column
    const float* args        # the component's parameters (NULL when none)
    float weight             # the column holds weight * value
    int native               # 1: written inside the step (by fn or an earlier group call);
                             # 0: filled in Python after the step (zeroed here)


cdef void reward_world(Sim* sim, const Atlas* atlas, const Params* prm, const TermSlot* slots,
                       int w) noexcept nogil
cdef void finalize_world(Sim* sim, const Params* prm, int w) noexcept nogil

cdef void term_paper(const Sim* sim, const Params* prm, const Atlas* atlas, const float* args,
                     int32_t w, float* out, int32_t stride) noexcept nogil

# The paper's eight terms (section 2.3) as components of the ABI (selfplaydrive_abi.h
# `sd_reward_term_fn`); declared here so that the module exports them in `__pyx_capi__`.
cdef void term_waypoint(const Sim* sim, const Params* prm, const Atlas* atlas, const float* args,
                        int32_t w, float* out, int32_t stride) noexcept nogil
cdef void term_collision(const Sim* sim, const Params* prm, const Atlas* atlas, const float* args,
                         int32_t w, float* out, int32_t stride) noexcept nogil
cdef void term_offroad(const Sim* sim, const Params* prm, const Atlas* atlas, const float* args,
                       int32_t w, float* out, int32_t stride) noexcept nogil
cdef void term_red_light(const Sim* sim, const Params* prm, const Atlas* atlas, const float* args,
                         int32_t w, float* out, int32_t stride) noexcept nogil
cdef void term_comfort(const Sim* sim, const Params* prm, const Atlas* atlas, const float* args,
                       int32_t w, float* out, int32_t stride) noexcept nogil
cdef void term_center(const Sim* sim, const Params* prm, const Atlas* atlas, const float* args,
                      int32_t w, float* out, int32_t stride) noexcept nogil
cdef void term_align(const Sim* sim, const Params* prm, const Atlas* atlas, const float* args,
                     int32_t w, float* out, int32_t stride) noexcept nogil
cdef void term_velocity(const Sim* sim, const Params* prm, const Atlas* atlas, const float* args,
                        int32_t w, float* out, int32_t stride) noexcept nogil
