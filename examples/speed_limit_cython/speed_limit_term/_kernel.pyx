# cython: language_level=3
"""The speed-limit term as an `sd_reward_term_fn` (selfplaydrive_abi.h)."""

from libc.stdint cimport int32_t, int64_t
from selfplaydrive_abi cimport Sim, Params, Atlas


cdef void speed_limit(const Sim* sim, const Params* prm, const Atlas* atlas, const float* args,
                      int32_t w, float* out, int32_t stride) noexcept nogil:
    """R = -args[0] * max(v - args[1], 0) for every active slot of world w (args: coef, limit [m/s])."""
    cdef int a, i
    cdef float over
    for a in range(sim.A):
        i = w * sim.A + a
        if sim.active[i]:
            over = sim.speed[i] - args[1]
            out[<int64_t>a * stride] = -args[0] * (over if over > 0 else <float>0.0)
