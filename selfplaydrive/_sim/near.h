/* Broad phase of the collision events (events.pyx, paper section 2.3): which of four bodies
 * (x, y, swept radius r, struct-of-arrays) may touch a body at (x0, y0) with swept radius r0,
 * by the conservative pre-test d^2 <= (r0 + r)^2 * 1.001 + 1e-4 [m^2] (far above float
 * rounding, so a pair it drops is one the exact test would reject too). Bodies that do not
 * take part have x = NaN: every comparison with NaN is false. SSE2 when the compiler offers
 * it, plain C otherwise; both evaluate the same float operations in the same order. */
#ifndef SELFPLAYDRIVE_NEAR_H
#define SELFPLAYDRIVE_NEAR_H

#include <stdint.h>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

/* bit l set when body k + l passes the pre-test */
static inline int spd_near4(const float *bx, const float *by, const float *br, int k, float x0,
                            float y0, float r0) {
#if defined(__SSE2__)
    __m128 dx = _mm_sub_ps(_mm_loadu_ps(bx + k), _mm_set1_ps(x0));
    __m128 dy = _mm_sub_ps(_mm_loadu_ps(by + k), _mm_set1_ps(y0));
    __m128 sr = _mm_add_ps(_mm_set1_ps(r0), _mm_loadu_ps(br + k));
    __m128 d2 = _mm_add_ps(_mm_mul_ps(dx, dx), _mm_mul_ps(dy, dy));
    __m128 lim = _mm_add_ps(_mm_mul_ps(_mm_mul_ps(sr, sr), _mm_set1_ps(1.001f)),
                            _mm_set1_ps(1e-4f));
    return _mm_movemask_ps(_mm_cmple_ps(d2, lim));
#else
    int l, m = 0;
    for (l = 0; l < 4; l++) {
        float dx = bx[k + l] - x0, dy = by[k + l] - y0, sr = r0 + br[k + l];
        float d2 = dx * dx + dy * dy, lim = sr * sr * 1.001f + 1e-4f;
        m |= (d2 <= lim) << l;
    }
    return m;
#endif
}

/* The observation's object candidates (observe.pyx): out[0 : n) = the indices k < nb, in
 * increasing order, of the bodies with (bx[k] - x0)^2 + (by[k] - y0)^2 <= r2, except k =
 * skip; returns n. bx, by hold nb entries padded with NaN to a multiple of 4; out needs room
 * for nb + 3 entries. */
#if defined(__SSE2__)
static const int32_t spd_near_pack4[16][4] __attribute__((aligned(16))) = {
    {0, 0, 0, 0}, {0, 0, 0, 0}, {1, 0, 0, 0}, {0, 1, 0, 0}, {2, 0, 0, 0}, {0, 2, 0, 0},
    {1, 2, 0, 0}, {0, 1, 2, 0}, {3, 0, 0, 0}, {0, 3, 0, 0}, {1, 3, 0, 0}, {0, 1, 3, 0},
    {2, 3, 0, 0}, {0, 2, 3, 0}, {1, 2, 3, 0}, {0, 1, 2, 3}};
static const int32_t spd_near_pop4[16] = {0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4};
#endif

static inline int spd_within(const float *bx, const float *by, int nb, float x0, float y0,
                             float r2, int skip, int32_t *out) {
    int k = 0, n = 0;
#if defined(__SSE2__)
    const __m128 vx = _mm_set1_ps(x0), vy = _mm_set1_ps(y0), vr = _mm_set1_ps(r2);
    __m128i pos = _mm_setzero_si128();
    const __m128i four = _mm_set1_epi32(4);
    for (; k < nb; k += 4) {
        __m128 dx = _mm_sub_ps(_mm_loadu_ps(bx + k), vx);
        __m128 dy = _mm_sub_ps(_mm_loadu_ps(by + k), vy);
        __m128 d2 = _mm_add_ps(_mm_mul_ps(dx, dx), _mm_mul_ps(dy, dy));
        int m = _mm_movemask_ps(_mm_cmple_ps(d2, vr));
        if ((unsigned)(skip - k) < 4u)
            m &= ~(1 << (skip - k));
        _mm_storeu_si128((__m128i *)(out + n),
                         _mm_add_epi32(pos, _mm_load_si128((const __m128i *)spd_near_pack4[m])));
        n += spd_near_pop4[m];
        pos = _mm_add_epi32(pos, four);
    }
#else
    for (; k < nb; k++) {
        float dx = bx[k] - x0, dy = by[k] - y0;
        float d2 = dx * dx + dy * dy;
        out[n] = k;
        n += (d2 <= r2) & (k != skip);
    }
#endif
    return n;
}

#endif
