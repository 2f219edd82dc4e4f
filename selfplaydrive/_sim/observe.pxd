# cython: language_level=3
from libc.stdint cimport int32_t, int64_t
from selfplaydrive._sim.common cimport Sim, Params, Atlas

cdef void observe_world(Sim* sim, const Atlas* atlas, const Params* prm, int w, float* obs,
                        int64_t stride) noexcept nogil

# The paper encoder (section 2.5) as a component of the ABI (selfplaydrive_abi.h
# `sd_encoder_fn`); declared here so that the module exports it in `__pyx_capi__`.
cdef void encode_paper(const Sim* sim, const Params* prm, const Atlas* atlas, const void* args,
                       int32_t w, float* obs, int32_t stride) noexcept nogil
