/* Observation row writer of observe.pyx (paper section 2.5): one road-segment row of
 * ROAD_DIM = 8 floats from a packed 8-float atlas record. SSE2 (every x86-64 CPU) when the
 * compiler offers it, plain C otherwise; both compute every value with the same float
 * operations in the same order (-ffp-contract=off), so the results are bit-identical.
 *
 * Record layout (sim/atlas.py `seg_rec`): mid x, mid y [m], dir x, dir y,
 * min(length / length_scale, 1), type / 4, signal group, global index (int32 bits).
 * Row layout (sim/layout.py ROAD_FEATURES): valid, dx, dy, cos_dir, sin_dir, length, type,
 * light_state; dx, dy in the ego frame divided by pos_scale. The light state (last float) is
 * written as 0 here; the caller overwrites it for traffic-light segments. */
#ifndef SELFPLAYDRIVE_ROWS_H
#define SELFPLAYDRIVE_ROWS_H

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

static inline float spd_clip(float v) {
    /* v < 1 ? v : 1 and v > -1 ? v : -1 compile to minss / maxss */
    v = v < 1.0f ? v : 1.0f;
    return v > -1.0f ? v : -1.0f;
}

/* c, s: ego heading cos / sin; cp, sp: the same divided by pos_scale. */
static inline void spd_road_row(float *r, const float *rec, float x, float y, float c, float s,
                                float cp, float sp) {
#if defined(__SSE2__)
    const __m128 one = _mm_set1_ps(1.0f), neg = _mm_set1_ps(-1.0f);
    const __m128 lo2 = _mm_castsi128_ps(_mm_set_epi32(0, 0, -1, -1));
    __m128 u = _mm_sub_ps(_mm_loadu_ps(rec), _mm_set_ps(0.0f, 0.0f, y, x)); /* ux uy dx dy */
    __m128 sw = _mm_shuffle_ps(u, u, _MM_SHUFFLE(2, 3, 0, 1));               /* uy ux dy dx */
    __m128 v = _mm_add_ps(_mm_mul_ps(u, _mm_set_ps(c, c, cp, cp)),
                          _mm_mul_ps(sw, _mm_set_ps(-s, s, -sp, sp)));
    __m128 w = _mm_and_ps(_mm_loadu_ps(rec + 4), lo2);                       /* len type 0 0 */
    v = _mm_max_ps(_mm_min_ps(v, one), neg);
    v = _mm_shuffle_ps(v, v, _MM_SHUFFLE(2, 1, 0, 3));                       /* v3 v0 v1 v2 */
    w = _mm_shuffle_ps(w, w, _MM_SHUFFLE(2, 1, 0, 3));                       /* 0 len type 0 */
    _mm_storeu_ps(r, _mm_move_ss(v, one));                                   /* 1 v0 v1 v2 */
    _mm_storeu_ps(r + 4, _mm_move_ss(w, v));                                 /* v3 len type 0 */
#else
    float ux = rec[0] - x, uy = rec[1] - y, dx = rec[2] - 0.0f, dy = rec[3] - 0.0f;
    r[0] = 1.0f;
    r[1] = spd_clip(ux * cp + uy * sp);
    r[2] = spd_clip(uy * cp + ux * -sp);
    r[3] = spd_clip(dx * c + dy * s);
    r[4] = spd_clip(dy * c + dx * -s);
    r[5] = rec[4];
    r[6] = rec[5];
    r[7] = 0.0f;
#endif
}

/* One object row (OBJ_DIM = 9: valid, dx, dy, cos, sin, length, width, vx, vy) from a body
 * record (x, y, cos, sin, vx, vy [world frame], length / length_scale, width / width_scale,
 * both clipped): positions rotated into the ego frame and divided by pos_scale (cp, sp),
 * velocities rotated and divided by max_speed (cv, sv). */
static inline void spd_object_row(float *r, const float *rec, float x, float y, float c, float s,
                                  float cp, float sp, float cv, float sv) {
#if defined(__SSE2__)
    const __m128 one = _mm_set1_ps(1.0f), neg = _mm_set1_ps(-1.0f);
    __m128 u = _mm_sub_ps(_mm_loadu_ps(rec), _mm_set_ps(0.0f, 0.0f, y, x)); /* ux uy oc os */
    __m128 sw = _mm_shuffle_ps(u, u, _MM_SHUFFLE(2, 3, 0, 1));               /* uy ux os oc */
    __m128 v = _mm_add_ps(_mm_mul_ps(u, _mm_set_ps(c, c, cp, cp)),
                          _mm_mul_ps(sw, _mm_set_ps(-s, s, -sp, sp)));
    __m128 q = _mm_loadu_ps(rec + 4);                                        /* vx vy l w */
    __m128 qs = _mm_shuffle_ps(q, q, _MM_SHUFFLE(3, 2, 0, 1));               /* vy vx l w */
    __m128 e = _mm_add_ps(_mm_mul_ps(q, _mm_set_ps(1.0f, 1.0f, cv, cv)),
                          _mm_mul_ps(qs, _mm_set_ps(0.0f, 0.0f, -sv, sv)));  /* e0 e1 l w */
    v = _mm_max_ps(_mm_min_ps(v, one), neg);
    e = _mm_max_ps(_mm_min_ps(e, one), neg);
    v = _mm_shuffle_ps(v, v, _MM_SHUFFLE(2, 1, 0, 3));                       /* v3 v0 v1 v2 */
    _mm_storeu_ps(r, _mm_move_ss(v, one));                                   /* 1 v0 v1 v2 */
    _mm_storeu_ps(r + 4, _mm_move_ss(_mm_shuffle_ps(e, e, _MM_SHUFFLE(0, 3, 2, 0)), v));
    _mm_store_ss(r + 8, _mm_shuffle_ps(e, e, _MM_SHUFFLE(1, 1, 1, 1)));
#else
    float ux = rec[0] - x, uy = rec[1] - y, oc = rec[2] - 0.0f, os = rec[3] - 0.0f;
    r[0] = 1.0f;
    r[1] = spd_clip(ux * cp + uy * sp);
    r[2] = spd_clip(uy * cp + ux * -sp);
    r[3] = spd_clip(oc * c + os * s);
    r[4] = spd_clip(os * c + oc * -s);
    r[5] = spd_clip(rec[6] * 1.0f + rec[6] * 0.0f);
    r[6] = spd_clip(rec[7] * 1.0f + rec[7] * 0.0f);
    r[7] = spd_clip(rec[4] * cv + rec[5] * sv);
    r[8] = spd_clip(rec[5] * cv + rec[4] * -sv);
#endif
}

#endif
