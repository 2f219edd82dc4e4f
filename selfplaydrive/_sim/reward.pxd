# cython: language_level=3
from selfplaydrive._sim.common cimport Sim, Params

cdef void reward_world(Sim* sim, const Params* prm, int w) noexcept nogil
cdef void finalize_world(Sim* sim, const Params* prm, int w) noexcept nogil
