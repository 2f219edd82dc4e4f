# cython: language_level=3
from libc.stdint cimport int32_t
from selfplaydrive._sim.common cimport Sim, Params, physics_fn

cdef struct PhysSlot:
    physics_fn fn      # the selected model; NULL: a Python model moved the vehicles already
    const float* args  # its float32 parameters (NULL when none)

cdef void physics_world(Sim* sim, const Params* prm, const PhysSlot* slot, int w) noexcept nogil

# the built-in models, exported in __pyx_capi__ (their capsule names give the signature that a
# user's Cython component must have: physics/components.py)
cdef void phys_bicycle(Sim* sim, const Params* prm, const float* args, int32_t w, float* state) noexcept nogil
cdef void phys_friction(Sim* sim, const Params* prm, const float* args, int32_t w, float* state) noexcept nogil
cdef void phys_jerk(Sim* sim, const Params* prm, const float* args, int32_t w, float* state) noexcept nogil
cdef void phys_delta(Sim* sim, const Params* prm, const float* args, int32_t w, float* state) noexcept nogil
