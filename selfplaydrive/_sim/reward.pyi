"""Type stub of the Cython module `selfplaydrive._sim.reward`: its kernels are cdef only, so
Python sees no names."""
