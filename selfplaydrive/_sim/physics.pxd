# cython: language_level=3
from selfplaydrive._sim.common cimport Sim, Params

cdef void physics_world(Sim* sim, const Params* prm, int w) noexcept nogil
