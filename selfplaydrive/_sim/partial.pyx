# cython: language_level=3
"""Partial observability as an observation encoder (issue #15 item 5; the paper's remarks on
partial observability as future work): the paper encoder (section 2.5, same layout, so models
and checkpoints work unchanged), then, on each agent's object rows,

1. occlusion: an object whose angular extent, seen from the ego's centre, is covered by nearer
   bodies (shadow casting on the oriented boxes) except for less than `visible_fraction` of it
   is hidden;
2. missed detections: each remaining object is dropped with probability `p_miss`;
3. perception noise: Gaussian noise on position [m], heading [rad] and speed [m/s];
4. false positives: Poisson(`fp_rate`) phantom boxes placed uniformly within the radius.

Hidden rows are removed (the kept rows move to the front) and the rows after them are zero,
like the paper encoder's padding. Random draws come from the world's own counter-based stream
(rng.pxd) keyed by the world's key mixed with a salt and indexed by (step, slot, row): a pure
function of the state, so the rollout does not depend on the thread count, and the world's
own stream (spawning, lights) is never advanced: with every effect off the observations are
the paper's bit for bit. The NumPy reference is selfplaydrive/testing/partial_reference.py;
docs/observation.md "Partial observability" gives the rules.
"""

from libc.math cimport atan2, cos, sin, sqrt, log, exp, fabs, M_PI
from libc.stdint cimport int32_t, int64_t, uint64_t, uintptr_t
from libc.string cimport memset, memmove
from selfplaydrive._sim.common cimport Sim, Params, Atlas, EGO_DIM, OBJ_DIM
from selfplaydrive._sim.observe cimport encode_paper
from selfplaydrive._sim.rng cimport mix64, rng_uniform

import numpy as np

# obs/encoders.py packs the same fields with ARGS_DTYPE (same order, no padding: 48 bytes)
ctypedef struct PartialArgs:
    uint64_t salt               # mixed into the world's key: the encoder's own stream
    int32_t occlusion           # 1: hide occluded objects
    float visible_fraction      # hidden when the visible part of the angular extent is below it
    float pos_std               # [m] position noise (per axis)
    float heading_std           # [rad]
    float speed_std             # [m/s]
    float p_miss                # probability of a missed detection
    float fp_rate               # expected false positives per agent and step
    float fp_length             # [m] size of a false positive
    float fp_width              # [m]
    float reserved

ARGS_FIELDS = ("salt", "occlusion", "visible_fraction", "pos_std", "heading_std", "speed_std",
               "p_miss", "fp_rate", "fp_length", "fp_width", "reserved")

# counter layout per agent and step: ROW_DRAWS draws per object row (rows < 4096), then the
# false positives from FP_BASE on
cdef enum:
    ROW_DRAWS = 8
    FP_BASE = 8 * 4096


def args_size():
    """sizeof(PartialArgs), checked against obs/encoders.py ARGS_DTYPE."""
    return sizeof(PartialArgs)


def encoder_address():
    """Address of `encode_partial` (an `sd_encoder_fn`)."""
    return <uintptr_t>encode_partial


def stream_key(uint64_t world_key, uint64_t salt):
    """Key of the encoder's stream for a world of key `world_key` (the reference uses it)."""
    return mix64(world_key ^ salt ^ <uint64_t>0x6F62735F70617274ULL)


cdef inline uint64_t row_counter(int32_t step, int a, int k) noexcept nogil:
    """First counter of object row k of slot a at episode step `step`."""
    return ((<uint64_t>step) << 40) + ((<uint64_t>a) << 24) + <uint64_t>(ROW_DRAWS * k)


cdef inline float clip1(double v) noexcept nogil:
    return <float>(1.0 if v > 1.0 else (-1.0 if v < -1.0 else v))


cdef inline void normal_pair(uint64_t key, uint64_t* ctr, double* z0, double* z1) noexcept nogil:
    """Two standard normals (Box-Muller) from two uniforms of the stream."""
    cdef double u1 = rng_uniform(key, ctr), u2 = rng_uniform(key, ctr)
    cdef double r = sqrt(-2.0 * log(1.0 - u1))
    z0[0] = r * cos(2.0 * M_PI * u2)
    z1[0] = r * sin(2.0 * M_PI * u2)


cdef void encode_partial(const Sim* sim, const Params* prm, const Atlas* atlas, const void* args,
                         int32_t w, float* obs, int32_t stride) noexcept nogil:
    """The paper encoder, then occlusion, misses, noise and false positives on the object rows
    of every active slot of world `w` (an `sd_encoder_fn`)."""
    cdef const PartialArgs* p = <const PartialArgs*>args
    cdef int a, i
    cdef uint64_t key = mix64(sim.rng_key[w] ^ p.salt ^ <uint64_t>0x6F62735F70617274ULL)
    cdef int32_t* counts = (<Sim*>sim).obj_rows   # the contract lets an encoder keep these
    # the world's float scratch, 8-byte aligned for doubles (scratch_floats() asks for the slack)
    cdef uintptr_t base = <uintptr_t>((<Sim*>sim).cand_d + <int64_t>w * sim.cand_cap)
    cdef double* scratch = <double*>((base + 7) & ~(<uintptr_t>7))
    encode_paper(sim, prm, atlas, NULL, w, obs, stride)
    if not (p.occlusion or p.p_miss > 0.0 or p.fp_rate > 0.0 or p.pos_std > 0.0
            or p.heading_std > 0.0 or p.speed_std > 0.0):
        return  # every effect off: the paper's rows (and no cost beyond this test)
    for a in range(sim.A):
        i = w * sim.A + a
        if sim.active[i]:
            counts[i] = postprocess(obs + <int64_t>a * stride + EGO_DIM, counts[i], sim.max_obj, p,
                                    key, sim.step[w], a, prm.pos_scale, prm.length_scale,
                                    prm.width_scale, prm.max_speed, prm.obs_radius, scratch)


cdef int postprocess(float* o, int n, int max_obj, const PartialArgs* p, uint64_t key,
                     int32_t step, int a, float pos_scale, float length_scale, float width_scale,
                     float max_speed, float radius, double* scratch) noexcept nogil:
    """Apply the four effects to `n` object rows at `o` (rows [n, max_obj) are zero); returns
    the new number of rows (rows after it are zero). `scratch`: scratch_doubles(max_obj)."""
    cdef int k, m = 0, j, nfp
    cdef uint64_t ctr
    cdef double u, z0, z1, z2, z3, th, r, ang
    cdef double* lo = scratch
    cdef double* hi = lo + max_obj
    cdef double* dist = hi + max_obj
    cdef double* phi = dist + max_obj
    cdef double* keep = phi + max_obj
    cdef double* ivl = keep + max_obj          # 2 * 2 * max_obj interval ends
    cdef int32_t* order = <int32_t*>(ivl + 4 * max_obj)
    cdef float* row
    if n > max_obj:
        n = max_obj
    if p.occlusion:
        angular_extents(o, n, pos_scale, length_scale, width_scale, lo, hi, dist, phi)
        by_distance(dist, n, order)
        for k in range(n):
            keep[k] = visible_fraction(n, k, lo, hi, dist, phi, order, ivl) >= p.visible_fraction
    else:
        for k in range(n):
            keep[k] = 1.0
    for k in range(n):
        if keep[k] == 0.0:
            continue
        ctr = row_counter(step, a, k)
        if p.p_miss > 0.0 and rng_uniform(key, &ctr) < p.p_miss:
            continue
        ctr = row_counter(step, a, k) + 1   # the noise's draws follow the miss draw's counter
        row = o + m * OBJ_DIM
        if m != k:
            memmove(row, o + k * OBJ_DIM, OBJ_DIM * sizeof(float))
        if p.pos_std > 0.0 or p.heading_std > 0.0 or p.speed_std > 0.0:
            normal_pair(key, &ctr, &z0, &z1)
            normal_pair(key, &ctr, &z2, &z3)
            add_noise(row, p, z0, z1, z2, z3, pos_scale, max_speed)
        m += 1
    if p.fp_rate > 0.0 and m < max_obj:
        ctr = row_counter(step, a, 0) + FP_BASE
        u = rng_uniform(key, &ctr)
        nfp = poisson(u, p.fp_rate, max_obj - m)
        for j in range(nfp):
            r = radius * sqrt(rng_uniform(key, &ctr))
            ang = 2.0 * M_PI * rng_uniform(key, &ctr)
            th = 2.0 * M_PI * rng_uniform(key, &ctr) - M_PI
            row = o + m * OBJ_DIM
            row[0] = 1.0
            row[1] = clip1(r * cos(ang) / pos_scale)
            row[2] = clip1(r * sin(ang) / pos_scale)
            row[3] = <float>cos(th)
            row[4] = <float>sin(th)
            row[5] = clip1(p.fp_length / length_scale)
            row[6] = clip1(p.fp_width / width_scale)
            row[7] = 0.0
            row[8] = 0.0
            m += 1
    if m < n:
        memset(o + m * OBJ_DIM, 0, (n - m) * OBJ_DIM * sizeof(float))
    return m


cdef inline int poisson(double u, double lam, int cap) noexcept nogil:
    """Poisson(lam) by inversion of one uniform, at most `cap`."""
    cdef int k = 0
    cdef double pk = exp(-lam), cdf = pk
    while u >= cdf and k < cap:
        k += 1
        pk *= lam / k
        cdf += pk
        if pk < 1e-300:
            break
    return k


cdef inline void add_noise(float* row, const PartialArgs* p, double z0, double z1, double z2,
                           double z3, float pos_scale, float max_speed) noexcept nogil:
    """Gaussian position, heading and speed noise on one object row (scaled units)."""
    cdef double c = row[3], s = row[4], th, ct, st, vx, vy, sp, sp2, c2
    if p.pos_std > 0.0:
        row[1] = clip1(row[1] + z0 * p.pos_std / pos_scale)
        row[2] = clip1(row[2] + z1 * p.pos_std / pos_scale)
    if p.heading_std > 0.0:
        th = z2 * p.heading_std
        ct = cos(th)
        st = sin(th)
        c2 = c * ct - s * st
        s = s * ct + c * st
        c = c2
        row[3] = clip1(c)
        row[4] = clip1(s)
    if p.speed_std > 0.0:
        vx = row[7] * <double>max_speed
        vy = row[8] * <double>max_speed
        sp = sqrt(vx * vx + vy * vy)
        sp2 = sp + z3 * p.speed_std
        if sp2 < 0.0:
            sp2 = 0.0
        if sp > 1e-6:
            vx *= sp2 / sp
            vy *= sp2 / sp
        else:  # a standing body: the noise goes along its (noisy) heading
            vx = c * sp2
            vy = s * sp2
        row[7] = clip1(vx / max_speed)
        row[8] = clip1(vy / max_speed)


cdef void angular_extents(const float* o, int n, float pos_scale, float length_scale,
                          float width_scale, double* lo, double* hi, double* dist,
                          double* phi) noexcept nogil:
    """Angular interval [lo, hi] of each object box around the direction of its centre `phi`,
    seen from the ego's centre (the origin of the ego frame), and its centre distance; a box
    that contains the origin gets dist = -1 (it neither occludes nor is occluded)."""
    cdef int k, q
    cdef double x, y, c, s, hl, hw, qx, qy, lx, ly, cr, dt, pa, pmin, pmax
    cdef double lcr = 0.0, ldt = 1.0, hcr = 0.0, hdt = 1.0
    for k in range(n):
        x = o[k * OBJ_DIM + 1] * <double>pos_scale
        y = o[k * OBJ_DIM + 2] * <double>pos_scale
        c = o[k * OBJ_DIM + 3]
        s = o[k * OBJ_DIM + 4]
        hl = 0.5 * o[k * OBJ_DIM + 5] * <double>length_scale
        hw = 0.5 * o[k * OBJ_DIM + 6] * <double>width_scale
        lx = -(c * x + s * y)      # the origin in the box's frame
        ly = -(-s * x + c * y)
        if fabs(lx) <= hl and fabs(ly) <= hw:
            lo[k] = 0.0
            hi[k] = 0.0
            dist[k] = -1.0
            continue
        dist[k] = sqrt(x * x + y * y)
        phi[k] = atan2(y, x)
        # the extreme corners by a pseudo-angle (monotonic in the angle, no trigonometry),
        # then the angle of those two only: 3 atan2 per box instead of 5
        pmin = 1e300
        pmax = -1e300
        for q in range(4):
            qx = x + (hl if q & 1 else -hl) * c - (hw if q & 2 else -hw) * s
            qy = y + (hl if q & 1 else -hl) * s + (hw if q & 2 else -hw) * c
            cr = x * qy - y * qx   # sin and cos of the corner angle minus the centre's, x |q| |c|
            dt = x * qx + y * qy
            pa = pseudo_angle(cr, dt)
            if pa < pmin:
                pmin = pa
                lcr = cr
                ldt = dt
            if pa > pmax:
                pmax = pa
                hcr = cr
                hdt = dt
        lo[k] = atan2(lcr, ldt)
        hi[k] = atan2(hcr, hdt)


cdef inline double pseudo_angle(double y, double x) noexcept nogil:
    """A strictly increasing function of atan2(y, x) on (-pi, pi], in (-2, 2]."""
    cdef double r = y / (fabs(x) + fabs(y))
    if x >= 0.0:
        return r
    return 2.0 - r if y >= 0.0 else -2.0 - r


cdef void by_distance(const double* dist, int n, int32_t* order) noexcept nogil:
    """order[0..n): object indices by increasing centre distance (insertion sort, stable)."""
    cdef int k, t
    cdef int32_t v
    for k in range(n):
        v = k
        t = k - 1
        while t >= 0 and dist[order[t]] > dist[v]:
            order[t + 1] = order[t]
            t -= 1
        order[t + 1] = v


cdef double visible_fraction(int n, int j, const double* lo, const double* hi,
                             const double* dist, const double* phi, const int32_t* order,
                             double* ivl) noexcept nogil:
    """Share of object j's angular extent not covered by the extents of nearer objects (centre
    distance below j's), each taken at its angle relative to j's centre (and the one 2 pi shift
    that can meet j's interval). `order`: the objects by increasing centre distance."""
    cdef int i, t, m = 0, q
    cdef double delta, a, b, width, covered, end, sa, sb, shift
    if dist[j] < 0.0 or hi[j] <= lo[j]:
        return 1.0
    width = hi[j] - lo[j]
    for t in range(n):
        i = order[t]
        if not dist[i] < dist[j]:
            break  # the rest are not nearer
        if dist[i] < 0.0:
            continue
        delta = phi[i] - phi[j]   # angle of i's centre from j's, in (-pi, pi]
        if delta > M_PI:
            delta -= 2.0 * M_PI
        elif delta <= -M_PI:
            delta += 2.0 * M_PI
        # j's interval holds 0 and is narrower than pi, i's is too: only the unshifted interval
        # and the one shifted back towards 0 can meet it
        shift = -2.0 * M_PI if delta > 0.0 else 2.0 * M_PI
        for q in range(2):
            a = delta + lo[i] + (shift if q else 0.0)
            b = delta + hi[i] + (shift if q else 0.0)
            if a < lo[j]:
                a = lo[j]
            if b > hi[j]:
                b = hi[j]
            if b > a:
                ivl[2 * m] = a
                ivl[2 * m + 1] = b
                m += 1
    if m == 0:
        return 1.0
    # insertion sort by start, then one sweep of the union
    for i in range(1, m):
        sa = ivl[2 * i]
        sb = ivl[2 * i + 1]
        t = i - 1
        while t >= 0 and ivl[2 * t] > sa:
            ivl[2 * t + 2] = ivl[2 * t]
            ivl[2 * t + 3] = ivl[2 * t + 1]
            t -= 1
        ivl[2 * t + 2] = sa
        ivl[2 * t + 3] = sb
    covered = 0.0
    a = ivl[0]
    end = ivl[1]
    for i in range(1, m):
        if ivl[2 * i] > end:
            covered += end - a
            a = ivl[2 * i]
            end = ivl[2 * i + 1]
        elif ivl[2 * i + 1] > end:
            end = ivl[2 * i + 1]
    covered += end - a
    return (width - covered) / width


def scratch_doubles(int max_obj):
    """Doubles of scratch `postprocess` needs: lo, hi, dist, phi, keep, 4 * max_obj interval ends
    and max_obj int32 indices (in max_obj doubles)."""
    return 10 * max_obj


def scratch_floats(int max_obj):
    """Floats of the world's cand_d scratch the encoder needs (with the alignment slack)."""
    return 2 * scratch_doubles(max_obj) + 2


def postprocess_rows(float[:, ::1] rows, int n, const unsigned char[::1] args, uint64_t key,
                     int step, int slot, float pos_scale, float length_scale, float width_scale,
                     float max_speed, float radius):
    """Run the kernel's post-processing on one agent's (max_obj, OBJ_DIM) object rows in place
    (tests compare it with the NumPy reference); `key` is `stream_key(world_key, salt)`.
    Returns the new row count."""
    if rows.shape[1] != OBJ_DIM:
        raise ValueError(f"rows: expected (max_obj, {OBJ_DIM}), got ({rows.shape[0]}, {rows.shape[1]})")
    if args.shape[0] != sizeof(PartialArgs):
        raise ValueError(f"args: expected {sizeof(PartialArgs)} bytes, got {args.shape[0]}")
    if not 0 <= n <= rows.shape[0]:
        raise ValueError(f"n: expected 0 <= n <= {rows.shape[0]}, got {n}")
    cdef int max_obj = rows.shape[0]
    scratch = np.zeros(scratch_doubles(max_obj), dtype=np.float64)
    cdef double[::1] sc = scratch
    return postprocess(&rows[0, 0], n, max_obj, <const PartialArgs*>&args[0], key, step, slot,
                       pos_scale, length_scale, width_scale, max_speed, radius, &sc[0])
