# cython: language_level=3
"""Python access to the counter-based RNG of rng.pxd (tests and the NumPy reference)."""

import numpy as np

from libc.stdint cimport uint64_t
from selfplaydrive._sim.rng cimport rng_uniform, rng_int


def uniform(uint64_t key, uint64_t counter, int n):
    """`n` uniforms in [0, 1) of stream `key` starting after `counter`; returns (values, counter)."""
    out = np.empty(n, dtype=np.float64)
    cdef double[::1] o = out
    cdef uint64_t c = counter
    cdef int i
    for i in range(n):
        o[i] = rng_uniform(key, &c)
    return out, c


def integers(uint64_t key, uint64_t counter, int n, int high):
    """`n` integers in [0, high) of stream `key` after `counter`; returns (values, counter)."""
    out = np.empty(n, dtype=np.int64)
    cdef long long[::1] o = out
    cdef uint64_t c = counter
    cdef int i
    for i in range(n):
        o[i] = rng_int(key, &c, high)
    return out, c
