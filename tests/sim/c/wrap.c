/* Compiled twice by tests/sim/test_simd_fallback.py: NAME(x) gives the prefix of each build. */
#include "rows.h"
#include "scan.h"
void NAME(road)(float *r, const float *rec, float x, float y, float c, float s, float cp, float sp) { spd_road_row(r, rec, x, y, c, s, cp, sp); }
void NAME(obj)(float *r, const float *rec, float x, float y, float c, float s, float cp, float sp, float cv, float sv) { spd_object_row(r, rec, x, y, c, s, cp, sp, cv, sv); }
void NAME(scan)(const float *mx, const float *my, int lo, int cnt, float x, float y, int32_t ilo, int32_t ihi, int32_t *in, int *ni, int32_t *sh, float *sd, int *ns) { spd_scan_split(mx, my, lo, cnt, x, y, ilo, ihi, in, ni, sh, sd, ns); }
