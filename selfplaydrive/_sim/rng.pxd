# cython: language_level=3
"""Counter-based RNG: each world owns a (key, counter) pair; a draw hashes key and counter.

The stream of a world depends only on its key and how many numbers it drew, never on the
thread that steps it, so rollouts are identical at any thread count (DESIGN principle 7).
The hash is SplitMix64's finaliser (Steele et al. 2014), a bijection with good avalanche.
"""

from libc.stdint cimport uint64_t


cdef inline uint64_t mix64(uint64_t z) noexcept nogil:
    z = (z ^ (z >> 30)) * <uint64_t>0xBF58476D1CE4E5B9ULL
    z = (z ^ (z >> 27)) * <uint64_t>0x94D049BB133111EBULL
    return z ^ (z >> 31)


cdef inline uint64_t rng_next(uint64_t key, uint64_t* ctr) noexcept nogil:
    """Next 64 random bits of the stream (key, *ctr); advances the counter."""
    cdef uint64_t c = ctr[0]
    ctr[0] = c + 1
    return mix64(key + (c + 1) * <uint64_t>0x9E3779B97F4A7C15ULL)


cdef inline double rng_uniform(uint64_t key, uint64_t* ctr) noexcept nogil:
    """Uniform double in [0, 1) from the top 53 bits."""
    return (rng_next(key, ctr) >> 11) * (1.0 / 9007199254740992.0)


cdef inline int rng_int(uint64_t key, uint64_t* ctr, int n) noexcept nogil:
    """Uniform integer in [0, n) (n small: the modulo bias is below 2^-50)."""
    return <int>((rng_next(key, ctr) >> 11) % <uint64_t>n)
