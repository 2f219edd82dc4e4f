/* Every SIMD level of _sim/rows.h, _sim/scan.h and _sim/near.h must agree bit for bit with the
 * plain-C build: wrap.c is compiled twice (prefix sse_: levels 0 plain C, 1 SSE2, 2 AVX2 when the
 * CPU has it; prefix c_: __SSE2__ undefined) and this driver compares them on random inputs
 * (tests/sim/test_simd_fallback.py). Prints "mismatches N; levels L; scan inner A/B shell C/D". */
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
int sse_init(int), c_init(int);
void sse_road_rows(float *, int32_t *, int, const float *, const float *, const float *, const float *,
                   ptrdiff_t, const int32_t *, float, float, float, float, float, float,
                   const int8_t *, int);
void c_road_rows(float *, int32_t *, int, const float *, const float *, const float *, const float *,
                 ptrdiff_t, const int32_t *, float, float, float, float, float, float,
                 const int8_t *, int);
void sse_obj_rows(float *, const int32_t *, int, const float *, float, float, float, float, float, float,
                  float, float);
void c_obj_rows(float *, const int32_t *, int, const float *, float, float, float, float, float, float,
                float, float);
void sse_scan(const float *, const float *, const int32_t *, int, float, float, int32_t, int32_t, int32_t,
              int32_t *, int *, int32_t *, float *, int *, int32_t *, float *, int *);
void c_scan(const float *, const float *, const int32_t *, int, float, float, int32_t, int32_t, int32_t,
            int32_t *, int *, int32_t *, float *, int *, int32_t *, float *, int *);
int sse_near4(const float *, const float *, const float *, int, float, float, float);
int c_near4(const float *, const float *, const float *, int, float, float, float);
int sse_within(const float *, const float *, int, float, float, float, int, int32_t *);
int c_within(const float *, const float *, int, float, float, float, int, int32_t *);

static float u(void) { return (float)rand() / RAND_MAX * 2.0f - 1.0f; }
static int32_t bits(float f) { int32_t i; memcpy(&i, &f, 4); return i; }

#define NS 4000
#define NR 203 /* rows per call: 25 AVX2 blocks + 0 SSE2 blocks + 3 plain-C rows at level 2 */
int main(void) {
    static float recs[NS * 8], mx[NS + 8], my[NS + 8], cols[4 * (NS + 8)], table[64 * 8];
    static int32_t group[NS + 8];
    static float o1[NR * 9], o2[NR * 9];
    static int32_t idx0[NR], idx1[NR], idx2[NR], cand[64];
    int8_t gstate[3] = {1, 2, 3};
    int bad = 0, level, levels = 0, it, k;
    int ref_in = 0, ref_sh = 0, got_in = 0, got_sh = 0;
    c_init(0);
    for (k = 0; k < NS; k++) {
        float *r = recs + 8 * k, h = u() * 3.14f;
        r[0] = u() * 150; r[1] = u() * 150; r[2] = cosf(h); r[3] = sinf(h);
        r[4] = (u() + 1) * 0.6f; r[5] = (rand() % 5) * 0.25f;
        r[6] = (u() + 1) * 12.0f; /* length [m] */
        r[7] = (rand() % 4 == 0) ? (float)(rand() % 5 - 1) : -1.0f; /* groups -1..3, G = 3 */
        mx[k] = r[0]; my[k] = r[1];
        for (it = 0; it < 4; it++) cols[it * (NS + 8) + k] = r[2 + it];
        group[k] = (int32_t)r[7];
    }
    for (k = 0; k < 64 * 8; k++) table[k] = u() * 60;
    for (level = 0; level <= 2; level++) {
        if (sse_init(level) != level) continue;
        levels = level + 1;
        for (it = 0; it < 400; it++) {
            float x = u() * 100, y = u() * 100, h = u() * 3.14f, c = cosf(h), s = sinf(h);
            int n = it % 2 ? NR : rand() % NR;
            /* runs of consecutive positions (the columns path) mixed with random ones */
            for (k = 0; k < n; k++) idx0[k] = (k > 0 && rand() % 8) ? (idx0[k - 1] + 1) % NS : rand() % NS;
            memcpy(idx1, idx0, sizeof idx0); memcpy(idx2, idx0, sizeof idx0);
            memset(o1, 0, sizeof o1); memset(o2, 0, sizeof o2);
            sse_road_rows(o1, idx1, n, recs, mx, my, cols, NS + 8, group, x, y, c, s, c * 0.01f,
                          s * 0.01f, gstate, 3);
            c_road_rows(o2, idx2, n, recs, mx, my, cols, NS + 8, group, x, y, c, s, c * 0.01f,
                        s * 0.01f, gstate, 3);
            if (memcmp(o1, o2, n * 8 * 4) || memcmp(idx1, idx2, n * 4)) bad++;
            n = rand() % 64;
            for (k = 0; k < n; k++) cand[k] = rand() % 64;
            memset(o1, 0, sizeof o1); memset(o2, 0, sizeof o2);
            sse_obj_rows(o1, cand, n, table, x, y, c, s, c * 0.01f, s * 0.01f, c * 0.025f, s * 0.025f);
            c_obj_rows(o2, cand, n, table, x, y, c, s, c * 0.01f, s * 0.01f, c * 0.025f, s * 0.025f);
            if (memcmp(o1, o2, n * 9 * 4)) bad++;
        }
        for (it = 0; it < 200; it++) {
            /* random columns (runs of any length, some with the events flag) */
            static int32_t cols[3 * 40], i1[NS + 8], i2[NS + 8], s1[NS], s2[NS], e1[NS + 8], e2[NS + 8];
            static float d1[NS], d2[NS], f1[NS + 8], f2[NS + 8];
            float x = u() * 100, y = u() * 100, lo = 30 + 20 * (u() + 1), hi = lo + 5 * (u() + 1), ev = 12;
            int32_t ilo = bits(lo * lo), ihi = bits(hi * hi), iev = bits(ev * ev);
            int nc = rand() % 40, n1 = 0, m1 = 0, q1 = 0, n2 = 0, m2 = 0, q2 = 0, total = 0;
            for (k = 0; k < nc; k++) {
                int a = rand() % (NS - 100), len = rand() % 100;
                cols[3 * k] = a; cols[3 * k + 1] = a + len; cols[3 * k + 2] = rand() % 2;
                total += len;
            }
            if (total + 8 > NS) continue;
            sse_scan(mx, my, cols, nc, x, y, ilo, ihi, iev, i1, &n1, s1, d1, &m1, e1, f1, &q1);
            c_scan(mx, my, cols, nc, x, y, ilo, ihi, iev, i2, &n2, s2, d2, &m2, e2, f2, &q2);
            if (n1 != n2 || m1 != m2 || q1 != q2 || memcmp(i1, i2, n1 * 4) || memcmp(s1, s2, m1 * 4) ||
                memcmp(d1, d2, m1 * 4) || memcmp(e1, e2, q1 * 4) ||
                memcmp(f1, f2, q1 * 4)) bad++;
            for (k = 0; k < nc; k++) {
                int p;
                for (p = cols[3 * k]; p < cols[3 * k + 1]; p++) {
                    float dx = mx[p] - x, dy = my[p] - y, d = dx * dx + dy * dy;
                    ref_in += d <= lo * lo;
                    ref_sh += d > lo * lo && d <= hi * hi;
                }
            }
            got_in += n1; got_sh += m1;
        }
        for (it = 0; it < 2000; it++) {
            float bx[44], by[44], br[44];
            int32_t w1[48], w2[48];
            int nb = rand() % 41, nb4 = (nb + 3) & ~3, skip = rand() % 44, n1, n2;
            float x0 = u() * 20, y0 = u() * 20;
            for (k = 0; k < 44; k++) {
                bx[k] = k < nb && rand() % 8 ? u() * 25 : NAN;
                by[k] = u() * 25; br[k] = (u() + 1) * 3;
            }
            for (k = 0; k < nb4; k += 4)
                if (sse_near4(bx, by, br, k, x0, y0, 2.5f) != c_near4(bx, by, br, k, x0, y0, 2.5f)) bad++;
            n1 = sse_within(bx, by, nb, x0, y0, 400.0f, skip, w1);
            n2 = c_within(bx, by, nb, x0, y0, 400.0f, skip, w2);
            if (n1 != n2 || memcmp(w1, w2, n1 * 4)) bad++;
        }
    }
    printf("mismatches %d; levels %d; scan inner %d/%d shell %d/%d\n", bad, levels, got_in, ref_in, got_sh, ref_sh);
    return bad != 0;
}
