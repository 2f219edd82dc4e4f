/* Compiled twice by tests/sim/test_simd_fallback.py: NAME(x) gives the prefix of each build
 * (sse_: the normal build, which has the plain-C, SSE2 and AVX2 levels of simd.h; c_: built
 * with __SSE2__ undefined, so only the plain-C code exists). */
#include "rows.h"
#include "scan.h"
#include "near.h"
int NAME(init)(int level) { return spd_scan_init(level); }
void NAME(road_rows)(float *o, int32_t *idx, int n, const float *recs, const float *mx, const float *my,
                     const float *cols, ptrdiff_t stride, const int32_t *group, float x,
                     float y, float c, float s, float cp, float sp, const int8_t *gstate, int G) {
    spd_road_cols rc = {mx, my, cols, stride, group};
    spd_road_rows(o, idx, n, recs, &rc, x, y, c, s, cp, sp, gstate, G);
}
void NAME(obj_rows)(float *o, const int32_t *cand, int n, const float *table, float x, float y, float c,
                    float s, float cp, float sp, float cv, float sv) {
    spd_object_rows(o, cand, n, table, x, y, c, s, cp, sp, cv, sv);
}
void NAME(scan)(const float *mx, const float *my, const int32_t *cols, int ncols, float x, float y,
                int32_t ilo, int32_t ihi, int32_t iev, int32_t *inner, int *ni, int32_t *shell,
                float *shell_d, int *ns, int32_t *ev, float *ev_d, int *ne) {
    spd_scan_columns(mx, my, cols, ncols, x, y, ilo, ihi, iev, inner, ni, shell, shell_d, ns, ev, ev_d,
                     ne);
}
int NAME(near4)(const float *bx, const float *by, const float *br, int k, float x0, float y0, float r0) {
    return spd_near4(bx, by, br, k, x0, y0, r0);
}
int NAME(within)(const float *bx, const float *by, int nb, float x0, float y0, float r2, int skip,
                 int32_t *out) {
    return spd_within(bx, by, nb, x0, y0, r2, skip, out);
}
