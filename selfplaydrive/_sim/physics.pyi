"""Type stub of the Cython module `selfplaydrive._sim.physics`: its kernels are cdef only, so
Python sees no names."""
