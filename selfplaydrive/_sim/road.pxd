# cython: language_level=3
from selfplaydrive._sim.common cimport Sim, Params, Atlas

cdef void road_world(Sim* sim, const Atlas* atlas, const Params* prm, int w) noexcept nogil
