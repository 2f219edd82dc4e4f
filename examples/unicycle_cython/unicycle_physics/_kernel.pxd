# cython: language_level=3
# Declared here, the function is exported in the module's __pyx_capi__ under its C signature,
# which KernelPhysics.from_cython checks against sd_physics_fn.
from libc.stdint cimport int32_t
from selfplaydrive_abi cimport Sim, Params

cdef void unicycle(Sim* sim, const Params* prm, const float* args, int32_t w, float* state) noexcept nogil
