# cython: language_level=3
from selfplaydrive._sim.common cimport Sim, Params, Atlas

cdef void lights_peds_world(Sim* sim, const Params* prm, int w) noexcept nogil
cdef void collisions_world(Sim* sim, const Params* prm, int w) noexcept nogil
cdef void peds_world(Sim* sim, const Params* prm, int w) noexcept nogil
