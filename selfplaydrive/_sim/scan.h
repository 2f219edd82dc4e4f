/* Inner loop of the road gather (road.pyx, paper section 2.5): squared midpoint distances
 * of one contiguous run of atlas positions, split without data-dependent branches into
 * "inner" (kept for sure), "shell" (to be selected) and dropped; optionally the candidates
 * within the events radius are listed too. Comparisons use the IEEE bit patterns, which
 * order non-negative floats like int32 (squared distances are >= 0; NaN goes nowhere).
 *
 * Three implementations (simd.h): plain C one candidate at a time (the definition), SSE2 four
 * and AVX2 eight at a time: distances with the same float operations, lane masks from
 * integer compares, kept positions packed to the front with a lane table (no branch per
 * candidate). All write the same entries in the same order (tests/sim/test_simd_fallback.py).
 * The SIMD versions read whole vectors: mx and my must be readable up to 7 floats past the
 * run (sim/atlas.py pads them); lanes past the run are masked out. */
#ifndef SELFPLAYDRIVE_SCAN_H
#define SELFPLAYDRIVE_SCAN_H

#include <stddef.h>
#include <stdint.h>
#include <string.h>
#include "simd.h"

static inline int32_t spd_fbits(float f) {
    int32_t i;
    memcpy(&i, &f, sizeof i);
    return i;
}

/* Arguments of every version, for one run [lo, lo + cnt) of atlas positions against (x, y):
 * ilo: bits of the inner bound (-1: no inner), ihi >= ilo: bits of the outer bound,
 * iev: bits of the events bound (used when with_ev).
 * inner[*ni...], shell[*ns...], shell_d[*ns...], ev[*ne...] and ev_d[*ne...] need room for
 * cnt + 7 more entries (the packed stores write whole vectors). ev_d gets the
 * squared distance of each ev entry (the same float as the split used). */

SPD_ALWAYS_INLINE void spd_scan_c(
    const float *restrict mx, const float *restrict my, int lo, int cnt, float x, float y,
    int32_t ilo, int32_t ihi, int32_t iev, int32_t *restrict inner, int *ni,
    int32_t *restrict shell, float *restrict shell_d, int *ns, int32_t *restrict ev,
    float *restrict ev_d, int *ne, const int with_ev) {
    /* pointer-sized counters: no sign extension per candidate */
    ptrdiff_t a = *ni, b = *ns, e = with_ev ? *ne : 0, t;
    uint32_t width = (uint32_t)ihi - (uint32_t)ilo;
    const float *px = mx + lo, *py = my + lo;
    for (t = 0; t < cnt; t++) {
        float dx = px[t] - x, dy = py[t] - y;
        float d = dx * dx + dy * dy;
        int32_t di = spd_fbits(d), p = lo + (int32_t)t;
        inner[a] = p;
        a += di <= ilo;
        if (with_ev) {
            ev[e] = p;
            ev_d[e] = d;
            e += di <= iev;
        }
        shell[b] = p;
        shell_d[b] = d;
        b += (uint32_t)di - (uint32_t)ilo - 1u < width;
    }
    *ni = (int)a;
    *ns = (int)b;
    if (with_ev)
        *ne = (int)e;
}

#if defined(__SSE2__)
/* lane numbers of the set bits of a 4-bit mask, packed to the front; and the bit counts */
static const int32_t spd_pack4[16][4] __attribute__((aligned(16))) = {
    {0, 0, 0, 0}, {0, 0, 0, 0}, {1, 0, 0, 0}, {0, 1, 0, 0}, {2, 0, 0, 0}, {0, 2, 0, 0},
    {1, 2, 0, 0}, {0, 1, 2, 0}, {3, 0, 0, 0}, {0, 3, 0, 0}, {1, 3, 0, 0}, {0, 1, 3, 0},
    {2, 3, 0, 0}, {0, 2, 3, 0}, {1, 2, 3, 0}, {0, 1, 2, 3}};
static const int32_t spd_pop4[16] = {0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4};

SPD_ALWAYS_INLINE void spd_scan_sse2(
    const float *restrict mx, const float *restrict my, int lo, int cnt, float x, float y,
    int32_t ilo, int32_t ihi, int32_t iev, int32_t *restrict inner, int *ni,
    int32_t *restrict shell, float *restrict shell_d, int *ns, int32_t *restrict ev,
    float *restrict ev_d, int *ne, const int with_ev) {
    ptrdiff_t a = *ni, b = *ns, e = with_ev ? *ne : 0, t;
    uint32_t width = (uint32_t)ihi - (uint32_t)ilo;
    const float *px = mx + lo, *py = my + lo;
    const __m128 vx = _mm_set1_ps(x), vy = _mm_set1_ps(y);
    const __m128i lo1 = _mm_set1_epi32(ilo + 1), ev1 = _mm_set1_epi32(iev + 1);
    const __m128i sgn = _mm_set1_epi32((int32_t)0x80000000u);
    const __m128i wid = _mm_set1_epi32((int32_t)(width ^ 0x80000000u));
    const __m128i four = _mm_set1_epi32(4);
    __m128i pos = _mm_set1_epi32(lo);
    for (t = 0; t < cnt; t += 4) {
        __m128 ex = _mm_sub_ps(_mm_loadu_ps(px + t), vx);
        __m128 ey = _mm_sub_ps(_mm_loadu_ps(py + t), vy);
        __m128 d4 = _mm_add_ps(_mm_mul_ps(ex, ex), _mm_mul_ps(ey, ey));
        __m128i di = _mm_castps_si128(d4);
        /* di <= ilo as ilo + 1 > di; shell: (uint)(di - ilo - 1) < width, unsigned compare
         * by flipping the sign bits */
        int mi = _mm_movemask_ps(_mm_castsi128_ps(_mm_cmpgt_epi32(lo1, di)));
        int ms = _mm_movemask_ps(_mm_castsi128_ps(
            _mm_cmplt_epi32(_mm_xor_si128(_mm_sub_epi32(di, lo1), sgn), wid)));
        int me = with_ev ? _mm_movemask_ps(_mm_castsi128_ps(_mm_cmpgt_epi32(ev1, di))) : 0;
        if (cnt - t < 4) {
            int valid = (1 << (cnt - t)) - 1; /* lanes past the run */
            mi &= valid;
            ms &= valid;
            me &= valid;
        }
        _mm_storeu_si128((__m128i *)(inner + a),
                         _mm_add_epi32(pos, _mm_load_si128((const __m128i *)spd_pack4[mi])));
        a += spd_pop4[mi];
        if (with_ev) {
            _mm_storeu_si128((__m128i *)(ev + e),
                             _mm_add_epi32(pos, _mm_load_si128((const __m128i *)spd_pack4[me])));
            if (me) {
                float dv[4];
                int j;
                _mm_storeu_ps(dv, d4);
                for (j = 0; j < spd_pop4[me]; j++)
                    ev_d[e + j] = dv[spd_pack4[me][j]];
            }
            e += spd_pop4[me];
        }
        if (ms) {
            /* the thin shell: few candidates, in lane order */
            float dv[4];
            int j;
            _mm_storeu_ps(dv, d4);
            for (j = 0; j < 4; j++) {
                if (ms >> j & 1) {
                    shell[b] = lo + (int32_t)t + j;
                    shell_d[b] = dv[j];
                    b++;
                }
            }
        }
        pos = _mm_add_epi32(pos, four);
    }
    *ni = (int)a;
    *ns = (int)b;
    if (with_ev)
        *ne = (int)e;
}
#endif

#if SPD_HAVE_AVX2
/* lane numbers of the set bits of an 8-bit mask, packed to the front; and the bit counts
 * (filled by spd_scan_tables at import) */
static uint8_t spd_pack8[256][8] __attribute__((aligned(8)));
static uint8_t spd_pop8[256];

static inline void spd_scan_tables(void) {
    int m, j, n;
    for (m = 0; m < 256; m++) {
        n = 0;
        for (j = 0; j < 8; j++)
            spd_pack8[m][j] = 0;
        for (j = 0; j < 8; j++)
            if (m >> j & 1)
                spd_pack8[m][n++] = (uint8_t)j;
        spd_pop8[m] = (uint8_t)n;
    }
}

/* Append the positions pos + (lanes of mask m), packed to the front, at dst[*n...] (and, with
 * the constant with_d, the same lanes of d8 at dst_d[*n...]); one whole-vector store each. */
SPD_ALWAYS_INLINE SPD_AVX2 void spd_put8(int32_t *restrict dst, float *restrict dst_d,
                                         ptrdiff_t *n, __m256i pos, __m256 d8, int m,
                                         const int with_d) {
    __m256i lane = _mm256_cvtepu8_epi32(_mm_loadl_epi64((const __m128i *)spd_pack8[m]));
    _mm256_storeu_si256((__m256i *)(dst + *n), _mm256_add_epi32(pos, lane));
    if (with_d)
        _mm256_storeu_ps(dst_d + *n, _mm256_permutevar8x32_ps(d8, lane));
    *n += spd_pop8[m];
}

/* Eight candidates from px, py (positions pos ...); `valid` masks lanes past the run. Every
 * list gets a whole-vector store of the packed lanes, so there is no branch per candidate: a
 * thin shell sets a lane in about one vector in seven, a branch there was mispredicted often. */
SPD_ALWAYS_INLINE SPD_AVX2 void spd_scan8_avx2(
    const float *px, const float *py, __m256 vx, __m256 vy, __m256i pos, int valid,
    __m256i lo1, __m256i sgn, __m256i wid, __m256i ev1, int32_t *restrict inner, ptrdiff_t *a,
    int32_t *restrict shell, float *restrict shell_d, ptrdiff_t *b, int32_t *restrict ev,
    float *restrict ev_d, ptrdiff_t *e, const int with_ev) {
    __m256 ex = _mm256_sub_ps(_mm256_loadu_ps(px), vx);
    __m256 ey = _mm256_sub_ps(_mm256_loadu_ps(py), vy);
    __m256 d8 = _mm256_add_ps(_mm256_mul_ps(ex, ex), _mm256_mul_ps(ey, ey));
    __m256i di = _mm256_castps_si256(d8);
    int mi = _mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpgt_epi32(lo1, di))) & valid;
    int ms = _mm256_movemask_ps(_mm256_castsi256_ps(
                 _mm256_cmpgt_epi32(wid, _mm256_xor_si256(_mm256_sub_epi32(di, lo1), sgn)))) &
             valid;
    spd_put8(inner, NULL, a, pos, d8, mi, 0);
    spd_put8(shell, shell_d, b, pos, d8, ms, 1);
    if (with_ev)
        spd_put8(ev, ev_d, e, pos, d8,
                 _mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpgt_epi32(ev1, di))) & valid, 1);
}

SPD_ALWAYS_INLINE SPD_AVX2 void spd_scan_avx2(
    const float *restrict mx, const float *restrict my, int lo, int cnt, float x, float y,
    int32_t ilo, int32_t ihi, int32_t iev, int32_t *restrict inner, int *ni,
    int32_t *restrict shell, float *restrict shell_d, int *ns, int32_t *restrict ev,
    float *restrict ev_d, int *ne, const int with_ev) {
    ptrdiff_t a = *ni, b = *ns, e = with_ev ? *ne : 0, t;
    uint32_t width = (uint32_t)ihi - (uint32_t)ilo;
    const float *px = mx + lo, *py = my + lo;
    const __m256 vx = _mm256_set1_ps(x), vy = _mm256_set1_ps(y);
    const __m256i lo1 = _mm256_set1_epi32(ilo + 1), ev1 = _mm256_set1_epi32(iev + 1);
    const __m256i sgn = _mm256_set1_epi32((int32_t)0x80000000u);
    const __m256i wid = _mm256_set1_epi32((int32_t)(width ^ 0x80000000u));
    const __m256i eight = _mm256_set1_epi32(8);
    __m256i pos = _mm256_set1_epi32(lo);
    /* whole vectors, then the last one with the lanes past the run masked out (a run ends
     * inside a vector 7 times in 8, so that branch is predicted well) */
    for (t = 0; t + 8 <= cnt; t += 8, pos = _mm256_add_epi32(pos, eight))
        spd_scan8_avx2(px + t, py + t, vx, vy, pos, 0xFF, lo1, sgn, wid, ev1, inner, &a, shell,
                       shell_d, &b, ev, ev_d, &e, with_ev);
    if (t < cnt)
        spd_scan8_avx2(px + t, py + t, vx, vy, pos, (1 << (cnt - t)) - 1, lo1, sgn, wid, ev1,
                       inner, &a, shell, shell_d, &b, ev, ev_d, &e, with_ev);
    *ni = (int)a;
    *ns = (int)b;
    if (with_ev)
        *ne = (int)e;
}

/* Columns (see spd_scan_columns) with the AVX2 loop inlined. */
static SPD_AVX2 void spd_scan_columns_avx2(const float *mx, const float *my, const int32_t *cols,
                                           int ncols, float x, float y, int32_t ilo,
                                           int32_t ihi, int32_t iev, int32_t *inner, int *ni,
                                           int32_t *shell, float *shell_d, int *ns,
                                           int32_t *ev, float *ev_d, int *ne) {
    int k;
    for (k = 0; k < ncols; k++) {
        const int32_t *c = cols + 3 * k;
        if (c[2])
            spd_scan_avx2(mx, my, c[0], c[1] - c[0], x, y, ilo, ihi, iev, inner, ni, shell,
                          shell_d, ns, ev, ev_d, ne, 1);
        else
            spd_scan_avx2(mx, my, c[0], c[1] - c[0], x, y, ilo, ihi, -1, inner, ni, shell,
                          shell_d, ns, NULL, NULL, NULL, 0);
    }
}
#endif

/* The SIMD level of this module (simd.h) and the lane tables. */
static inline int spd_scan_init(int want) {
#if SPD_HAVE_AVX2
    spd_scan_tables();
#endif
    return spd_simd_init(want);
}

/* inner / shell split of one run (plain C) */
static inline void spd_scan_split_c(const float *restrict mx, const float *restrict my, int lo,
                                    int cnt, float x, float y, int32_t ilo, int32_t ihi,
                                    int32_t *restrict inner, int *ni, int32_t *restrict shell,
                                    float *restrict shell_d, int *ns) {
    spd_scan_c(mx, my, lo, cnt, x, y, ilo, ihi, -1, inner, ni, shell, shell_d, ns, NULL, NULL,
               NULL, 0);
}

/* Grid columns of the road gather: column k is the atlas range [c[0], c[1]) (c = cols + 3k);
 * when c[2] is set (the column meets the events disc) the positions with squared distance
 * bits <= iev are listed in ev, their squared distances in ev_d. One call per agent (the
 * loop setup is paid once). */
static inline void spd_scan_columns(const float *mx, const float *my, const int32_t *cols,
                                    int ncols, float x, float y, int32_t ilo, int32_t ihi,
                                    int32_t iev, int32_t *inner, int *ni, int32_t *shell,
                                    float *shell_d, int *ns, int32_t *ev, float *ev_d,
                                    int *ne) {
    int k;
#if SPD_HAVE_AVX2
    if (spd_simd >= 2) {
        spd_scan_columns_avx2(mx, my, cols, ncols, x, y, ilo, ihi, iev, inner, ni, shell,
                              shell_d, ns, ev, ev_d, ne);
        return;
    }
#endif
    for (k = 0; k < ncols; k++) {
        const int32_t *c = cols + 3 * k;
#if defined(__SSE2__)
        if (spd_simd >= 1) {
            if (c[2])
                spd_scan_sse2(mx, my, c[0], c[1] - c[0], x, y, ilo, ihi, iev, inner, ni, shell,
                              shell_d, ns, ev, ev_d, ne, 1);
            else
                spd_scan_sse2(mx, my, c[0], c[1] - c[0], x, y, ilo, ihi, -1, inner, ni, shell,
                              shell_d, ns, NULL, NULL, NULL, 0);
            continue;
        }
#endif
        if (c[2])
            spd_scan_c(mx, my, c[0], c[1] - c[0], x, y, ilo, ihi, iev, inner, ni, shell, shell_d,
                       ns, ev, ev_d, ne, 1);
        else
            spd_scan_c(mx, my, c[0], c[1] - c[0], x, y, ilo, ihi, -1, inner, ni, shell, shell_d,
                       ns, NULL, NULL, NULL, 0);
    }
}

#endif
