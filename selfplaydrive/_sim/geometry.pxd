# cython: language_level=3
"""Inline geometry shared by the kernels: angle wrap, oriented-box tests (SAT), segment
clipping, and partial selection of the k nearest candidates. All boxes are given by centre
(cx, cy), heading cos/sin (c, s) and half extents (hl along the heading, hw across) [m].
"""

from libc.math cimport fabs, floor, sqrt, M_PI
from libc.stdint cimport int32_t, int64_t


cdef inline float wrap_angle(float a) noexcept nogil:
    """Angle in (-pi, pi] [rad]."""
    if a > M_PI or a <= -M_PI:
        a = a - 2.0 * M_PI * floor((a + M_PI) / (2.0 * M_PI))
        if a <= -M_PI:
            a = a + 2.0 * M_PI
    return a


cdef inline float box_radius(float hl, float hw) noexcept nogil:
    """Half diagonal of a box [m] (bounding circle)."""
    return sqrt(hl * hl + hw * hw)


cdef inline bint obb_overlap(float ax, float ay, float ac, float as_, float ahl, float ahw,
                             float bx, float by, float bc, float bs, float bhl, float bhw) noexcept nogil:
    """Separating-axis test of two oriented boxes; touching counts as overlap."""
    cdef float dx = bx - ax, dy = by - ay
    # axes of A: (ac, as_) and (-as_, ac); of B: (bc, bs) and (-bs, bc)
    cdef float cab = fabs(ac * bc + as_ * bs)   # |a_u . b_u|
    cdef float sab = fabs(ac * bs - as_ * bc)   # |a_u . b_v| = |a_v . b_u|
    if fabs(dx * ac + dy * as_) > ahl + bhl * cab + bhw * sab:
        return False
    if fabs(-dx * as_ + dy * ac) > ahw + bhl * sab + bhw * cab:
        return False
    if fabs(dx * bc + dy * bs) > bhl + ahl * cab + ahw * sab:
        return False
    if fabs(-dx * bs + dy * bc) > bhw + ahl * sab + ahw * cab:
        return False
    return True


cdef inline bint seg_box(float px, float py, float qx, float qy,
                         float cx, float cy, float c, float s, float hl, float hw) noexcept nogil:
    """True when segment p-q touches the box (Liang-Barsky clipping in the box frame)."""
    cdef float ux = (px - cx) * c + (py - cy) * s
    cdef float uy = -(px - cx) * s + (py - cy) * c
    cdef float vx = (qx - cx) * c + (qy - cy) * s - ux
    cdef float vy = -(qx - cx) * s + (qy - cy) * c - uy
    cdef float t0 = 0.0, t1 = 1.0
    if not clip1(-vx, ux + hl, &t0, &t1):
        return False
    if not clip1(vx, hl - ux, &t0, &t1):
        return False
    if not clip1(-vy, uy + hw, &t0, &t1):
        return False
    if not clip1(vy, hw - uy, &t0, &t1):
        return False
    return True


cdef inline bint clip1(float p, float q, float* t0, float* t1) noexcept nogil:
    """One Liang-Barsky half-plane p * t <= q; narrows [t0, t1], False when empty."""
    cdef float r
    if p == 0.0:
        return q >= 0.0
    r = q / p
    if p < 0.0:
        if r > t1[0]:
            return False
        if r > t0[0]:
            t0[0] = r
    else:
        if r < t0[0]:
            return False
        if r < t1[0]:
            t1[0] = r
    return True


cdef inline bint segs_cross(float ax, float ay, float bx, float by,
                            float cx, float cy, float dx, float dy) noexcept nogil:
    """True when segments a-b and c-d intersect (collinear overlaps ignored)."""
    cdef float d1 = (dx - cx) * (ay - cy) - (dy - cy) * (ax - cx)
    cdef float d2 = (dx - cx) * (by - cy) - (dy - cy) * (bx - cx)
    cdef float d3 = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
    cdef float d4 = (bx - ax) * (dy - ay) - (by - ay) * (dx - ax)
    return ((d1 > 0) != (d2 > 0)) and ((d3 > 0) != (d4 > 0)) and d1 != d2 and d3 != d4


cdef inline bint cand_less(float da, int32_t ia, float db, int32_t ib,
                           const int32_t* key) noexcept nogil:
    """Order by distance, then by key[index] (or the index itself when key is NULL): a strict
    total order, so selection is deterministic. The key is only read on a distance tie."""
    if da != db:
        return da < db
    if key != NULL:
        return key[ia] < key[ib]
    return ia < ib


cdef inline void select_nearest(float* d, int32_t* idx, int n, int k,
                                const int32_t* key=NULL) noexcept nogil:
    """Partially reorder (d, idx)[:n] so its first k entries are the k smallest by (distance,
    key[idx]) (quickselect); key NULL: ties by idx itself."""
    cdef int lo = 0, hi = n - 1, i, j, mid
    cdef float pd, td
    cdef int32_t pi, ti
    if k >= n or k <= 0:
        return
    while hi > lo:
        mid = lo + (hi - lo) // 2
        pd = d[mid]
        pi = idx[mid]
        i = lo
        j = hi
        while i <= j:
            while cand_less(d[i], idx[i], pd, pi, key):
                i += 1
            while cand_less(pd, pi, d[j], idx[j], key):
                j -= 1
            if i <= j:
                td = d[i]; d[i] = d[j]; d[j] = td
                ti = idx[i]; idx[i] = idx[j]; idx[j] = ti
                i += 1
                j -= 1
        if k - 1 <= j:
            hi = j
        elif k - 1 >= i:
            lo = i
        else:
            return


cdef inline void swap_cand(float* d, int32_t* idx, int a, int b) noexcept nogil:
    cdef float td = d[a]
    cdef int32_t ti = idx[a]
    d[a] = d[b]; d[b] = td
    idx[a] = idx[b]; idx[b] = ti


cdef inline int bin64(float v, float dmin, float inv) noexcept nogil:
    """Bin in [0, 63] of v in [dmin, dmin + 64 / inv] (clamped in float: no int overflow)."""
    v = (v - dmin) * inv
    # max / min in float (maxss / minss: no branch); NaN goes to bin 0
    v = v if v > 0.0 else 0.0
    v = v if v < 63.0 else 63.0
    return <int>v


cdef inline void select_nearest_binned(float* d, int32_t* idx, int n, int k, float dmin,
                                       float dmax, const int32_t* key=NULL) noexcept nogil:
    """Same result set as select_nearest for values in [dmin, dmax], in two linear passes: a
    64-bin histogram finds the bin holding the k-th value, entries of lower bins move to the
    front, and quickselect runs only on the boundary bin (robust O(n), no bad pivots)."""
    cdef int counts[64]
    cdef int b, t, m = 0, p, cum = 0, kb
    cdef float inv = 64.0 / (dmax - dmin) if dmax > dmin else 0.0
    if k >= n or k <= 0:
        return
    for b in range(64):
        counts[b] = 0
    for t in range(n):
        counts[bin64(d[t], dmin, inv)] += 1
    kb = 0
    while kb < 63 and cum + counts[kb] < k:
        cum += counts[kb]
        kb += 1
    # partitions without a data-dependent branch: swap unconditionally, advance on a match
    # (entries between the front and t never match, so a swap that does not advance only
    # exchanges two of them)
    for t in range(n):
        swap_cand(d, idx, t, m)
        m += bin64(d[m], dmin, inv) < kb
    p = m
    for t in range(m, n):
        swap_cand(d, idx, t, p)
        p += bin64(d[p], dmin, inv) == kb
    select_nearest(d + m, idx + m, p - m, k - m, key)
