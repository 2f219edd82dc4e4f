/* Both builds of _sim/rows.h and _sim/scan.h (SSE2 and plain C) must agree bit for bit: wrap.c is compiled
 * twice (NAME prefix sse_ / c_; the second with __SSE2__ undefined) and this driver compares them on random
 * records (tests/sim/test_simd_fallback.py). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <stdint.h>
void sse_road(float*, const float*, float, float, float, float, float, float);
void c_road(float*, const float*, float, float, float, float, float, float);
void sse_obj(float*, const float*, float, float, float, float, float, float, float, float);
void c_obj(float*, const float*, float, float, float, float, float, float, float, float);
void sse_scan(const float*, const float*, int, int, float, float, int32_t, int32_t, int32_t*, int*, int32_t*, float*, int*);
void c_scan(const float*, const float*, int, int, float, float, int32_t, int32_t, int32_t*, int*, int32_t*, float*, int*);
static float u(void) { return (float)rand() / RAND_MAX * 2.0f - 1.0f; }
int main(void) {
    int bad = 0;
    for (int it = 0; it < 200000; it++) {
        float rec[8] = {u()*150, u()*150, u(), u(), (u()+1)*0.6f, (rand()%5)*0.25f, (float)(rand()%3-1), 0};
        float x = u()*100, y = u()*100, h = u()*3.14f, c = cosf(h), s = sinf(h);
        float a[9], b[9];
        memset(a, 0, sizeof a); memset(b, 0, sizeof b);
        sse_road(a, rec, x, y, c, s, c*0.01f, s*0.01f); c_road(b, rec, x, y, c, s, c*0.01f, s*0.01f);
        if (memcmp(a, b, 8*sizeof(float))) bad++;
        float orec[8] = {u()*150, u()*150, u(), u(), u()*40, u()*40, (u()+1)*0.5f, (u()+1)*0.5f};
        sse_obj(a, orec, x, y, c, s, c*0.01f, s*0.01f, c*0.025f, s*0.025f); c_obj(b, orec, x, y, c, s, c*0.01f, s*0.01f, c*0.025f, s*0.025f);
        if (memcmp(a, b, 9*sizeof(float))) bad++;
    }
    float mx[1000], my[1000];
    for (int i = 0; i < 1000; i++) { mx[i] = u()*100; my[i] = u()*100; }
    int32_t i1[1000], i2[1000], s1[1000], s2[1000]; float d1[1000], d2[1000];
    float lo = 40*40, hi = 50*50; int32_t ilo, ihi; memcpy(&ilo, &lo, 4); memcpy(&ihi, &hi, 4);
    int n1 = 0, m1 = 0, n2 = 0, m2 = 0;
    sse_scan(mx, my, 3, 997, 1.5f, -2.f, ilo, ihi, i1, &n1, s1, d1, &m1);
    c_scan(mx, my, 3, 997, 1.5f, -2.f, ilo, ihi, i2, &n2, s2, d2, &m2);
    if (n1 != n2 || m1 != m2 || memcmp(i1, i2, n1*4) || memcmp(s1, s2, m1*4) || memcmp(d1, d2, m1*4)) bad++;
    int ref_in = 0, ref_sh = 0;
    for (int i = 3; i < 1000; i++) { float dx = mx[i]-1.5f, dy = my[i]+2.f, d = dx*dx+dy*dy; ref_in += d <= lo; ref_sh += d > lo && d <= hi; }
    printf("mismatches %d; scan inner %d/%d shell %d/%d\n", bad, n1, ref_in, m1, ref_sh);
    return bad != 0;
}
