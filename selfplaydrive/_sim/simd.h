/* Runtime choice of the SIMD implementation of the kernels' inner loops (rows.h, scan.h):
 *   0  plain C (the definition; every compiler),
 *   1  SSE2 (every x86-64 CPU; compiled when the compiler offers it),
 *   2  AVX2 (x86-64 CPUs that have it; GCC or clang, via target attributes, so the module is
 *      still built for the x86-64 baseline).
 * All levels evaluate the same float operations in the same order (the extension is built
 * with -ffp-contract=off: no fused multiply-adds), so they give bit-identical results; the
 * level only changes speed. Each extension module has its own copy of `spd_simd`, set once
 * at import (selfplaydrive._sim.simd_level) before any step runs. */
#ifndef SELFPLAYDRIVE_SIMD_H
#define SELFPLAYDRIVE_SIMD_H

#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#if defined(__GNUC__) && (defined(__x86_64__) || defined(__i386__)) && defined(__SSE2__) && \
    !defined(SPD_NO_AVX2)
#define SPD_HAVE_AVX2 1
#include <immintrin.h>
#define SPD_AVX2 __attribute__((target("avx2")))
#else
#define SPD_HAVE_AVX2 0
#endif

/* inline a helper that takes a constant flag, so each use compiles its own loop */
#if defined(__GNUC__)
#define SPD_ALWAYS_INLINE static inline __attribute__((always_inline))
#else
#define SPD_ALWAYS_INLINE static inline
#endif

static int spd_simd = 0;

/* Highest level the build and the CPU support, capped at `want` (< 0: no cap); returns it. */
static inline int spd_simd_init(int want) {
    int best = 0;
#if defined(__SSE2__)
    best = 1;
#endif
#if SPD_HAVE_AVX2
    __builtin_cpu_init();
    if (__builtin_cpu_supports("avx2"))
        best = 2;
#endif
    spd_simd = (want >= 0 && want < best) ? want : best;
    return spd_simd;
}

#endif
