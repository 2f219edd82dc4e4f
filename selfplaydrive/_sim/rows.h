/* Observation row writers of observe.pyx (paper section 2.5): the road-segment rows
 * (ROAD_DIM = 8 floats) and object rows (OBJ_DIM = 9) of one agent, from packed 8-float
 * records. Three implementations (simd.h): plain C one row at a time (the definition), SSE2
 * four rows at a time, AVX2 eight rows at a time. The SIMD versions load whole records,
 * transpose them so that every vector holds one feature of 4 or 8 rows, compute exactly the
 * float operations of the plain-C row in the same order and transpose back, so all three
 * write bit-identical rows (tests/sim/test_simd_fallback.py).
 *
 * Road record layout (sim/atlas.py `seg_rec`): mid x, mid y [m], dir x, dir y,
 * min(length / length_scale, 1), type / 4, length [m], signal group. The road events
 * (road.pyx) read the same records, so the lines they load are those the rows need next.
 * Road row layout (obs/layout.py ROAD_FEATURES): valid, dx, dy, cos_dir, sin_dir, length,
 * type, light_state; dx, dy in the ego frame divided by pos_scale.
 * Object record (observe.pyx `body_table`): x, y, cos, sin, vx, vy [world frame],
 * length / length_scale, width / width_scale (both clipped). Object row: valid, dx, dy, cos,
 * sin, length, width, vx, vy; velocities rotated and divided by max_speed. */
#ifndef SELFPLAYDRIVE_ROWS_H
#define SELFPLAYDRIVE_ROWS_H

#include <stddef.h>
#include <stdint.h>
#include <string.h>
#include "simd.h"

static inline float spd_clip(float v) {
    /* v < 1 ? v : 1 and v > -1 ? v : -1 compile to minss / maxss */
    v = v < 1.0f ? v : 1.0f;
    return v > -1.0f ? v : -1.0f;
}

/* ---------------------------------------------------------------- plain C (definition) */

/* c, s: ego heading cos / sin; cp, sp: the same divided by pos_scale. The light state (last
 * float) is written as 0; spd_road_light sets it for traffic-light segments. */
static inline void spd_road_row(float *r, const float *rec, float x, float y, float c, float s,
                                float cp, float sp) {
    float ux = rec[0] - x, uy = rec[1] - y, dx = rec[2], dy = rec[3];
    r[0] = 1.0f;
    r[1] = spd_clip(ux * cp + uy * sp);
    r[2] = spd_clip(uy * cp + ux * -sp);
    r[3] = spd_clip(dx * c + dy * s);
    r[4] = spd_clip(dy * c + dx * -s);
    r[5] = rec[4];
    r[6] = rec[5];
    r[7] = 0.0f;
}

/* light state / 3 of signal group g (no group: g < 0; groups the world does not have: 0) */
static inline void spd_road_light_g(float *r, int32_t g, const int8_t *gstate, int G) {
    if (g >= 0 && g < G)
        r[7] = gstate[g] * (float)(1.0 / 3.0);
}

/* the same from a record (lane 6 holds the group as a float) */
static inline void spd_road_light(float *r, const float *rec, const int8_t *gstate, int G) {
    if (rec[7] >= 0.0f)
        spd_road_light_g(r, (int32_t)rec[7], gstate, G);
}

/* The road features as columns, for blocks of rows whose segments are consecutive atlas
 * positions p0 .. p0 + 3 (read by the SSE2 version only): mid x, mid y, dir x, dir y,
 * length, type at mx[p], my[p], cols[k * stride + p] (k = 0..3), and the group
 * (sim/atlas.py). The values are the records' own, so a block read from columns gives the
 * same rows. */
typedef struct {
    const float *mx, *my, *cols;
    ptrdiff_t stride;
    const int32_t *group;
} spd_road_cols;

/* cv, sv: cos / sin divided by max_speed. */
static inline void spd_object_row(float *r, const float *rec, float x, float y, float c, float s,
                                  float cp, float sp, float cv, float sv) {
    float ux = rec[0] - x, uy = rec[1] - y, oc = rec[2], os = rec[3];
    r[0] = 1.0f;
    r[1] = spd_clip(ux * cp + uy * sp);
    r[2] = spd_clip(uy * cp + ux * -sp);
    r[3] = spd_clip(oc * c + os * s);
    r[4] = spd_clip(os * c + oc * -s);
    r[5] = spd_clip(rec[6]);
    r[6] = spd_clip(rec[7]);
    r[7] = spd_clip(rec[4] * cv + rec[5] * sv);
    r[8] = spd_clip(rec[5] * cv + rec[4] * -sv);
}

/* Road rows k0..n-1: row k from record recs[8 * idx[k]]. */
static inline void spd_road_rows_c(float *o, const int32_t *idx, int k0, int n, const float *recs,
                                   float x, float y, float c, float s, float cp, float sp,
                                   const int8_t *gstate, int G) {
    int k;
    for (k = k0; k < n; k++) {
        const float *rec = recs + 8 * (ptrdiff_t)idx[k];
        float *r = o + 8 * (ptrdiff_t)k;
        spd_road_row(r, rec, x, y, c, s, cp, sp);
        spd_road_light(r, rec, gstate, G);
    }
}

/* Object rows k0..n-1: row k from record table[8 * cand[k]]. */
static inline void spd_object_rows_c(float *o, const int32_t *cand, int k0, int n,
                                     const float *table, float x, float y, float c, float s,
                                     float cp, float sp, float cv, float sv) {
    int k;
    for (k = k0; k < n; k++)
        spd_object_row(o + 9 * (ptrdiff_t)k, table + 8 * (ptrdiff_t)cand[k], x, y, c, s, cp, sp,
                       cv, sv);
}

/* ---------------------------------------------------------------- SSE2, four rows */
#if defined(__SSE2__)
#define SPD_CLIP4(v) _mm_max_ps(_mm_min_ps((v), one), neg)

static inline int spd_road_rows_sse2(float *o, const int32_t *idx, int n, const float *recs,
                                     const spd_road_cols *rc, float x, float y, float c, float s,
                                     float cp, float sp, const int8_t *gstate, int G) {
    const __m128 one = _mm_set1_ps(1.0f), neg = _mm_set1_ps(-1.0f), zero = _mm_setzero_ps();
    const __m128 X = _mm_set1_ps(x), Y = _mm_set1_ps(y), C = _mm_set1_ps(c), S = _mm_set1_ps(s);
    const __m128 NS = _mm_set1_ps(-s), CP = _mm_set1_ps(cp), SP = _mm_set1_ps(sp);
    const __m128 NSP = _mm_set1_ps(-sp);
    const __m128i iota = _mm_set_epi32(3, 2, 1, 0);
    int k = 0, j;
    for (; k + 4 <= n; k += 4) {
        const float *q[4];
        float *r = o + 8 * (ptrdiff_t)k;
        int lights, p0 = idx[k];
        __m128 a0, a1, a2, a3, b0, b1;
        __m128i ib = _mm_loadu_si128((const __m128i *)(idx + k));
        if (_mm_movemask_ps(_mm_castsi128_ps(
                _mm_cmpeq_epi32(ib, _mm_add_epi32(_mm_set1_epi32(p0), iota)))) == 15) {
            /* consecutive segments: the features straight from the columns */
            const ptrdiff_t st = rc->stride;
            __m128i g = _mm_loadu_si128((const __m128i *)(rc->group + p0));
            a0 = _mm_loadu_ps(rc->mx + p0);
            a1 = _mm_loadu_ps(rc->my + p0);
            a2 = _mm_loadu_ps(rc->cols + p0);
            a3 = _mm_loadu_ps(rc->cols + st + p0);
            b0 = _mm_loadu_ps(rc->cols + 2 * st + p0);
            b1 = _mm_loadu_ps(rc->cols + 3 * st + p0);
            lights = _mm_movemask_ps(_mm_castsi128_ps(_mm_cmpgt_epi32(g, _mm_set1_epi32(-1))));
            for (j = 0; j < 4; j++)
                q[j] = recs + 8 * (ptrdiff_t)(p0 + j);
        } else {
            __m128 b2, b3;
            const int32_t *ip = idx + k;
            for (j = 0; j < 4; j++)
                q[j] = recs + 8 * (ptrdiff_t)ip[j];
            a0 = _mm_loadu_ps(q[0]);
            a1 = _mm_loadu_ps(q[1]);
            a2 = _mm_loadu_ps(q[2]);
            a3 = _mm_loadu_ps(q[3]);
            b0 = _mm_loadu_ps(q[0] + 4);
            b1 = _mm_loadu_ps(q[1] + 4);
            b2 = _mm_loadu_ps(q[2] + 4);
            b3 = _mm_loadu_ps(q[3] + 4);
            _MM_TRANSPOSE4_PS(a0, a1, a2, a3); /* mid x, mid y, dir x, dir y */
            _MM_TRANSPOSE4_PS(b0, b1, b2, b3); /* length, type, length [m], group */
            lights = _mm_movemask_ps(_mm_cmpge_ps(b3, zero));
        }
        __m128 ux = _mm_sub_ps(a0, X), uy = _mm_sub_ps(a1, Y);
        __m128 v1 = SPD_CLIP4(_mm_add_ps(_mm_mul_ps(ux, CP), _mm_mul_ps(uy, SP)));
        __m128 v2 = SPD_CLIP4(_mm_add_ps(_mm_mul_ps(uy, CP), _mm_mul_ps(ux, NSP)));
        __m128 v3 = SPD_CLIP4(_mm_add_ps(_mm_mul_ps(a2, C), _mm_mul_ps(a3, S)));
        __m128 v4 = SPD_CLIP4(_mm_add_ps(_mm_mul_ps(a3, C), _mm_mul_ps(a2, NS)));
        __m128 w0 = one, w1 = v1, w2 = v2, w3 = v3;
        __m128 z0 = v4, z1 = b0, z2 = b1, z3 = zero;
        _MM_TRANSPOSE4_PS(w0, w1, w2, w3);
        _MM_TRANSPOSE4_PS(z0, z1, z2, z3);
        _mm_storeu_ps(r, w0);
        _mm_storeu_ps(r + 4, z0);
        _mm_storeu_ps(r + 8, w1);
        _mm_storeu_ps(r + 12, z1);
        _mm_storeu_ps(r + 16, w2);
        _mm_storeu_ps(r + 20, z2);
        _mm_storeu_ps(r + 24, w3);
        _mm_storeu_ps(r + 28, z3);
        if (lights)
            for (j = 0; j < 4; j++)
                if (lights >> j & 1)
                    spd_road_light(r + 8 * j, q[j], gstate, G);
    }
    return k;
}

static inline int spd_object_rows_sse2(float *o, const int32_t *cand, int n, const float *table,
                                       float x, float y, float c, float s, float cp, float sp,
                                       float cv, float sv) {
    const __m128 one = _mm_set1_ps(1.0f), neg = _mm_set1_ps(-1.0f), zero = _mm_setzero_ps();
    const __m128 X = _mm_set1_ps(x), Y = _mm_set1_ps(y), C = _mm_set1_ps(c), S = _mm_set1_ps(s);
    const __m128 NS = _mm_set1_ps(-s), CP = _mm_set1_ps(cp), SP = _mm_set1_ps(sp);
    const __m128 NSP = _mm_set1_ps(-sp), CV = _mm_set1_ps(cv), SV = _mm_set1_ps(sv);
    const __m128 NSV = _mm_set1_ps(-sv);
    int k = 0, j;
    for (; k + 4 <= n; k += 4) {
        const float *q[4];
        float *r = o + 9 * (ptrdiff_t)k;
        float last[4];
        const int32_t *ip = cand + k;
        for (j = 0; j < 4; j++)
            q[j] = table + 8 * (ptrdiff_t)ip[j];
        __m128 a0 = _mm_loadu_ps(q[0]), a1 = _mm_loadu_ps(q[1]), a2 = _mm_loadu_ps(q[2]);
        __m128 a3 = _mm_loadu_ps(q[3]);
        __m128 b0 = _mm_loadu_ps(q[0] + 4), b1 = _mm_loadu_ps(q[1] + 4);
        __m128 b2 = _mm_loadu_ps(q[2] + 4), b3 = _mm_loadu_ps(q[3] + 4);
        _MM_TRANSPOSE4_PS(a0, a1, a2, a3); /* x, y, cos, sin */
        _MM_TRANSPOSE4_PS(b0, b1, b2, b3); /* vx, vy, length, width */
        __m128 ux = _mm_sub_ps(a0, X), uy = _mm_sub_ps(a1, Y);
        __m128 w0 = one;
        __m128 w1 = SPD_CLIP4(_mm_add_ps(_mm_mul_ps(ux, CP), _mm_mul_ps(uy, SP)));
        __m128 w2 = SPD_CLIP4(_mm_add_ps(_mm_mul_ps(uy, CP), _mm_mul_ps(ux, NSP)));
        __m128 w3 = SPD_CLIP4(_mm_add_ps(_mm_mul_ps(a2, C), _mm_mul_ps(a3, S)));
        __m128 z0 = SPD_CLIP4(_mm_add_ps(_mm_mul_ps(a3, C), _mm_mul_ps(a2, NS)));
        __m128 z1 = SPD_CLIP4(b2);
        __m128 z2 = SPD_CLIP4(b3);
        __m128 z3 = SPD_CLIP4(_mm_add_ps(_mm_mul_ps(b0, CV), _mm_mul_ps(b1, SV)));
        __m128 e = SPD_CLIP4(_mm_add_ps(_mm_mul_ps(b1, CV), _mm_mul_ps(b0, NSV)));
        (void)zero;
        _MM_TRANSPOSE4_PS(w0, w1, w2, w3);
        _MM_TRANSPOSE4_PS(z0, z1, z2, z3);
        _mm_storeu_ps(last, e);
        _mm_storeu_ps(r, w0);
        _mm_storeu_ps(r + 4, z0);
        _mm_storeu_ps(r + 9, w1);
        _mm_storeu_ps(r + 13, z1);
        _mm_storeu_ps(r + 18, w2);
        _mm_storeu_ps(r + 22, z2);
        _mm_storeu_ps(r + 27, w3);
        _mm_storeu_ps(r + 31, z3);
        r[8] = last[0];
        r[17] = last[1];
        r[26] = last[2];
        r[35] = last[3];
    }
    return k;
}
#undef SPD_CLIP4
#endif

/* ---------------------------------------------------------------- AVX2, eight rows */
#if SPD_HAVE_AVX2
#define SPD_CLIP8(v) _mm256_max_ps(_mm256_min_ps((v), one), neg)

/* 8 x 8 transpose: r[j] lane l <- r[l] lane j */
static inline SPD_AVX2 void spd_tr8(__m256 *r) {
    __m256 t0 = _mm256_unpacklo_ps(r[0], r[1]), t1 = _mm256_unpackhi_ps(r[0], r[1]);
    __m256 t2 = _mm256_unpacklo_ps(r[2], r[3]), t3 = _mm256_unpackhi_ps(r[2], r[3]);
    __m256 t4 = _mm256_unpacklo_ps(r[4], r[5]), t5 = _mm256_unpackhi_ps(r[4], r[5]);
    __m256 t6 = _mm256_unpacklo_ps(r[6], r[7]), t7 = _mm256_unpackhi_ps(r[6], r[7]);
    __m256 s0 = _mm256_shuffle_ps(t0, t2, 0x44), s1 = _mm256_shuffle_ps(t0, t2, 0xEE);
    __m256 s2 = _mm256_shuffle_ps(t1, t3, 0x44), s3 = _mm256_shuffle_ps(t1, t3, 0xEE);
    __m256 s4 = _mm256_shuffle_ps(t4, t6, 0x44), s5 = _mm256_shuffle_ps(t4, t6, 0xEE);
    __m256 s6 = _mm256_shuffle_ps(t5, t7, 0x44), s7 = _mm256_shuffle_ps(t5, t7, 0xEE);
    r[0] = _mm256_permute2f128_ps(s0, s4, 0x20);
    r[1] = _mm256_permute2f128_ps(s1, s5, 0x20);
    r[2] = _mm256_permute2f128_ps(s2, s6, 0x20);
    r[3] = _mm256_permute2f128_ps(s3, s7, 0x20);
    r[4] = _mm256_permute2f128_ps(s0, s4, 0x31);
    r[5] = _mm256_permute2f128_ps(s1, s5, 0x31);
    r[6] = _mm256_permute2f128_ps(s2, s6, 0x31);
    r[7] = _mm256_permute2f128_ps(s3, s7, 0x31);
}

/* light states of rows r[0 .. n) (cold: a block with a traffic-light line) */
static __attribute__((noinline, cold)) void spd_road_lights(float *r, const int32_t *ip, int n,
                                                            const float *recs,
                                                            const int8_t *gstate, int G) {
    int j;
    for (j = 0; j < n; j++)
        spd_road_light(r + 8 * j, recs + 8 * (ptrdiff_t)ip[j], gstate, G);
}

/* rows k and k + 1 of the records at qa and qb (see spd_road_rows_avx2); returns the high
 * halves, whose lane 7 (the signal group) says whether a row needs its light state */
SPD_ALWAYS_INLINE SPD_AVX2 __m256 spd_road_pair_avx2(float *r, const float *qa, const float *qb,
                                                     __m256 XY, __m256 M1, __m256 M2,
                                                     __m256 one, __m256 neg, __m256 zero) {
    __m256 lo4 = _mm256_insertf128_ps(_mm256_castps128_ps256(_mm_loadu_ps(qa)),
                                      _mm_loadu_ps(qb), 1);
    __m256 hi4 = _mm256_insertf128_ps(_mm256_castps128_ps256(_mm_loadu_ps(qa + 4)),
                                      _mm_loadu_ps(qb + 4), 1);
    __m256 u = _mm256_sub_ps(lo4, XY);          /* ux, uy, dir x, dir y (two rows) */
    __m256 w = _mm256_permute_ps(u, 0xB1);      /* uy, ux, dir y, dir x */
    __m256 v = SPD_CLIP8(_mm256_add_ps(_mm256_mul_ps(u, M1), _mm256_mul_ps(w, M2)));
    /* (1, dx, dy, cos) and (sin, length, type, 0) per row */
    __m256 a = _mm256_castsi256_ps(
        _mm256_alignr_epi8(_mm256_castps_si256(v), _mm256_castps_si256(one), 12));
    __m256 b = _mm256_blend_ps(
        _mm256_castsi256_ps(
            _mm256_alignr_epi8(_mm256_castps_si256(hi4), _mm256_castps_si256(v), 12)),
        zero, 0x88);
    _mm256_storeu_ps(r, _mm256_permute2f128_ps(a, b, 0x20));
    _mm256_storeu_ps(r + 8, _mm256_permute2f128_ps(a, b, 0x31));
    return hi4;
}

/* Two rows per vector, no transposes: the rotated pairs (mid x, mid y) and (dir x, dir y) sit
 * in the low half of a record, so both rows' low halves share one vector and the rotation is
 * u * (cp, cp, c, c) + swap(u) * (sp, -sp, s, -s), with swap an in-lane shuffle; byte shifts
 * then slide the results one float to the right behind the constant 1 and in front of
 * (length, type) from the high halves. The products and sums are the plain-C row's, so the
 * rows are bit-identical. (An 8 x 8 transpose in and out took twice the shuffles.) Four rows
 * per iteration share the loop overhead and one light test: the group lanes of both high
 * halves are ANDed (a light line has a group >= 0, sign bit clear). */
static SPD_AVX2 int spd_road_rows_avx2(float *o, const int32_t *idx, int n, const float *recs,
                                       const spd_road_cols *rc, float x, float y, float c,
                                       float s, float cp, float sp, const int8_t *gstate,
                                       int G) {
    const __m256 XY = _mm256_setr_ps(x, y, 0.0f, 0.0f, x, y, 0.0f, 0.0f);
    const __m256 M1 = _mm256_setr_ps(cp, cp, c, c, cp, cp, c, c);
    const __m256 M2 = _mm256_setr_ps(sp, -sp, s, -s, sp, -sp, s, -s);
    const __m256 one = _mm256_set1_ps(1.0f), neg = _mm256_set1_ps(-1.0f);
    const __m256 zero = _mm256_setzero_ps();
    const int32_t *ip = idx;
    float *r = o;
    int k = 0;
    (void)rc;
    for (; k + 4 <= n; k += 4, ip += 4, r += 32) {
        __m256 h0 = spd_road_pair_avx2(r, recs + 8 * (ptrdiff_t)ip[0], recs + 8 * (ptrdiff_t)ip[1],
                                       XY, M1, M2, one, neg, zero);
        __m256 h1 = spd_road_pair_avx2(r + 16, recs + 8 * (ptrdiff_t)ip[2],
                                       recs + 8 * (ptrdiff_t)ip[3], XY, M1, M2, one, neg, zero);
        /* the group (lane 7 of each record) is -1 except on traffic-light lines */
        if (__builtin_expect((_mm256_movemask_ps(_mm256_and_ps(h0, h1)) & 0x88) != 0x88, 0))
            spd_road_lights(r, ip, 4, recs, gstate, G);
    }
    for (; k + 2 <= n; k += 2, ip += 2, r += 16) {
        __m256 h = spd_road_pair_avx2(r, recs + 8 * (ptrdiff_t)ip[0], recs + 8 * (ptrdiff_t)ip[1],
                                      XY, M1, M2, one, neg, zero);
        if (__builtin_expect((_mm256_movemask_ps(h) & 0x88) != 0x88, 0))
            spd_road_lights(r, ip, 2, recs, gstate, G);
    }
    return k;
}

static SPD_AVX2 int spd_object_rows_avx2(float *o, const int32_t *cand, int n,
                                         const float *table, float x, float y, float c, float s,
                                         float cp, float sp, float cv, float sv) {
    const __m256 one = _mm256_set1_ps(1.0f), neg = _mm256_set1_ps(-1.0f);
    const __m256 X = _mm256_set1_ps(x), Y = _mm256_set1_ps(y), C = _mm256_set1_ps(c);
    const __m256 S = _mm256_set1_ps(s), NS = _mm256_set1_ps(-s), CP = _mm256_set1_ps(cp);
    const __m256 SP = _mm256_set1_ps(sp), NSP = _mm256_set1_ps(-sp), CV = _mm256_set1_ps(cv);
    const __m256 SV = _mm256_set1_ps(sv), NSV = _mm256_set1_ps(-sv);
    int k = 0, j;
    for (; k + 8 <= n; k += 8) {
        __m256 v[8], e;
        float *r = o + 9 * (ptrdiff_t)k;
        float last[8];
        const int32_t *ip = cand + k;
        for (j = 0; j < 8; j++)
            v[j] = _mm256_loadu_ps(table + 8 * (ptrdiff_t)ip[j]);
        spd_tr8(v); /* x, y, cos, sin, vx, vy, length, width */
        __m256 ux = _mm256_sub_ps(v[0], X), uy = _mm256_sub_ps(v[1], Y);
        __m256 oc = v[2], os = v[3], vx = v[4], vy = v[5];
        e = SPD_CLIP8(_mm256_add_ps(_mm256_mul_ps(vy, CV), _mm256_mul_ps(vx, NSV)));
        v[0] = one;
        v[1] = SPD_CLIP8(_mm256_add_ps(_mm256_mul_ps(ux, CP), _mm256_mul_ps(uy, SP)));
        v[2] = SPD_CLIP8(_mm256_add_ps(_mm256_mul_ps(uy, CP), _mm256_mul_ps(ux, NSP)));
        v[3] = SPD_CLIP8(_mm256_add_ps(_mm256_mul_ps(oc, C), _mm256_mul_ps(os, S)));
        v[4] = SPD_CLIP8(_mm256_add_ps(_mm256_mul_ps(os, C), _mm256_mul_ps(oc, NS)));
        v[5] = SPD_CLIP8(v[6]);
        v[6] = SPD_CLIP8(v[7]);
        v[7] = SPD_CLIP8(_mm256_add_ps(_mm256_mul_ps(vx, CV), _mm256_mul_ps(vy, SV)));
        spd_tr8(v);
        _mm256_storeu_ps(last, e);
        for (j = 0; j < 8; j++) {
            _mm256_storeu_ps(r + 9 * j, v[j]);
            r[9 * j + 8] = last[j];
        }
    }
    return k;
}
#undef SPD_CLIP8
#endif

/* ---------------------------------------------------------------- dispatch */

/* The road rows of one agent: o[8 k ...] from record recs[8 idx[k]] for k < n (or, for
 * blocks of consecutive positions, from the same values in columns `rc`). */
static inline void spd_road_rows(float *o, const int32_t *idx, int n, const float *recs,
                                 const spd_road_cols *rc, float x, float y, float c, float s,
                                 float cp, float sp, const int8_t *gstate, int G) {
    int k = 0;
#if SPD_HAVE_AVX2
    if (spd_simd >= 2)
        k = spd_road_rows_avx2(o, idx, n, recs, rc, x, y, c, s, cp, sp, gstate, G);
#endif
#if defined(__SSE2__)
    if (spd_simd >= 1)
        k += spd_road_rows_sse2(o + 8 * (ptrdiff_t)k, idx + k, n - k, recs, rc, x, y, c, s, cp,
                                sp, gstate, G);
#endif
    spd_road_rows_c(o, idx, k, n, recs, x, y, c, s, cp, sp, gstate, G);
}

/* The object rows of one agent: o[9 k ...] from record table[8 cand[k]] for k < n. */
static inline void spd_object_rows(float *o, const int32_t *cand, int n, const float *table,
                                   float x, float y, float c, float s, float cp, float sp,
                                   float cv, float sv) {
    int k = 0;
#if SPD_HAVE_AVX2
    if (spd_simd >= 2)
        k = spd_object_rows_avx2(o, cand, n, table, x, y, c, s, cp, sp, cv, sv);
#endif
#if defined(__SSE2__)
    if (spd_simd >= 1)
        k += spd_object_rows_sse2(o + 9 * (ptrdiff_t)k, cand + k, n - k, table, x, y, c, s, cp,
                                  sp, cv, sv);
#endif
    spd_object_rows_c(o, cand, k, n, table, x, y, c, s, cp, sp, cv, sv);
}

#endif
