# Declaring the function here makes Cython export it in the module's __pyx_capi__, with its C
# signature as the capsule name: KernelEncoder.from_cython checks that name against the ABI.
from libc.stdint cimport int32_t
from selfplaydrive_abi cimport Sim, Params, Atlas

cdef void ego_objects(const Sim* sim, const Params* prm, const Atlas* atlas, const void* args,
                      int32_t w, float* out, int32_t stride) noexcept nogil
