# cython: language_level=3
from libc.stdint cimport int32_t, int64_t
from selfplaydrive._sim.common cimport Sim, Params, Atlas

cdef void observe_world(Sim* sim, const Atlas* atlas, const Params* prm, int w, float* obs,
                        int64_t stride) noexcept nogil

# The paper encoder (section 2.5) as a component of the ABI (selfplaydrive_abi.h
# `sd_encoder_fn`); declared here so that the module exports it in `__pyx_capi__`.
cdef void encode_paper(const Sim* sim, const Params* prm, const Atlas* atlas, const void* args,
                       int32_t w, float* obs, int32_t stride) noexcept nogil

# The per-agent pieces of observe_world, for encoders that extend the paper's rows agent by agent
# while they are hot in cache (_sim/obs_rules.pyx): the world's body table in its scratch, then ego,
# object and road rows of slot i. `body_floats`: floats of cand_d the body table uses.
cdef int body_floats(int A, int S, int P) noexcept nogil
cdef int body_table(Sim* sim, const Params* prm, int w, float* t, int32_t* owner) noexcept nogil
cdef void write_ego(Sim* sim, const Params* prm, int i, float* o) noexcept nogil
cdef void write_objects(Sim* sim, const Params* prm, int w, int i, int own, const float* table,
                        int nb, float* o) noexcept nogil
cdef void write_road(Sim* sim, const Atlas* atlas, const Params* prm, int w, int i,
                     float* o) noexcept nogil
