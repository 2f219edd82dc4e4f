# cython: language_level=3
from libc.stdint cimport int32_t
from selfplaydrive._sim.common cimport Sim, Params, Atlas

# The rule terms of issue #15 (paper section 5.1) as components of the ABI (selfplaydrive_abi.h
# `sd_reward_term_fn`); declared here so that the module exports them in `__pyx_capi__`. Their
# args are the packed tables of rewards/rule_tables.py (header, parameters, per-map grids).
cdef void term_red_intersection(const Sim* sim, const Params* prm, const Atlas* atlas,
                                const float* args, int32_t w, float* out,
                                int32_t stride) noexcept nogil
cdef void term_stop_sign(const Sim* sim, const Params* prm, const Atlas* atlas, const float* args,
                         int32_t w, float* out, int32_t stride) noexcept nogil
cdef void term_crosswalk_yield(const Sim* sim, const Params* prm, const Atlas* atlas,
                               const float* args, int32_t w, float* out,
                               int32_t stride) noexcept nogil
cdef void term_wrong_way(const Sim* sim, const Params* prm, const Atlas* atlas, const float* args,
                         int32_t w, float* out, int32_t stride) noexcept nogil
cdef void term_turn_lane(const Sim* sim, const Params* prm, const Atlas* atlas, const float* args,
                         int32_t w, float* out, int32_t stride) noexcept nogil
