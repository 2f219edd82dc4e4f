/* Inner loop of the road gather (events.pyx, paper section 2.5): squared midpoint distances
 * of one contiguous run of atlas positions, split without branches into "inner" (kept for
 * sure), "shell" (to be selected) and dropped. Comparisons use the IEEE bit patterns, which
 * order non-negative floats like int32 (squared distances are >= 0; NaN goes nowhere). */
#ifndef SELFPLAYDRIVE_SCAN_H
#define SELFPLAYDRIVE_SCAN_H

#include <stddef.h>
#include <stdint.h>
#include <string.h>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

static inline int32_t spd_fbits(float f) {
    int32_t i;
    memcpy(&i, &f, sizeof i);
    return i;
}

/* ilo: bits of the inner bound (-1: no inner), ihi >= ilo: bits of the outer bound.
 * inner[*ni...], shell[*ns...] and shell_d[*ns...] must have room for cnt more entries. */
static inline void spd_scan_split(const float *restrict mx, const float *restrict my, int lo,
                                  int cnt, float x, float y, int32_t ilo, int32_t ihi,
                                  int32_t *restrict inner, int *ni, int32_t *restrict shell,
                                  float *restrict shell_d, int *ns) {
    /* pointer-sized counters: no sign extension per candidate */
    ptrdiff_t a = *ni, b = *ns, t = 0;
    uint32_t width = (uint32_t)ihi - (uint32_t)ilo;
    const float *px = mx + lo, *py = my + lo;
#if defined(__SSE2__)
    /* four distances at a time (the same IEEE operations as the scalar tail), then the
     * branch-free split lane by lane */
    const __m128 vx = _mm_set1_ps(x), vy = _mm_set1_ps(y);
    for (; t + 4 <= cnt; t += 4) {
        __m128 ex = _mm_sub_ps(_mm_loadu_ps(px + t), vx);
        __m128 ey = _mm_sub_ps(_mm_loadu_ps(py + t), vy);
        __m128 d4 = _mm_add_ps(_mm_mul_ps(ex, ex), _mm_mul_ps(ey, ey));
        int32_t di[4], j;
        float dv[4];
        _mm_storeu_ps(dv, d4);
        _mm_storeu_si128((__m128i *)di, _mm_castps_si128(d4));
        for (j = 0; j < 4; j++) {
            int32_t p = lo + (int32_t)t + j;
            inner[a] = p;
            a += di[j] <= ilo;
            shell[b] = p;
            shell_d[b] = dv[j];
            b += (uint32_t)di[j] - (uint32_t)ilo - 1u < width;
        }
    }
#endif
    for (; t < cnt; t++) {
        float dx = px[t] - x, dy = py[t] - y;
        float d = dx * dx + dy * dy;
        int32_t di = spd_fbits(d), p = lo + (int32_t)t;
        inner[a] = p;
        a += di <= ilo;
        shell[b] = p;
        shell_d[b] = d;
        b += (uint32_t)di - (uint32_t)ilo - 1u < width;
    }
    *ni = (int)a;
    *ns = (int)b;
}

#endif
