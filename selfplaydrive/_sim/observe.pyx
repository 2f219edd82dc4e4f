# cython: language_level=3
"""Observations (paper section 2.5), written once per active agent row. Padding rows are zero:
only the observation stage writes `obs` (the env exposes it read-only), so a slot's rows past
the count it wrote last time are still zero, and only the rows between the new and the old
count are cleared (on average 38 of 63 object rows are padding: clearing them every step was
~16 % of the observation's bytes). Layout and feature names: selfplaydrive/obs/layout.py. Every value is
scaled and clipped to [-1, 1]; positions and directions are in the ego frame (x forward,
y left)."""

from libc.stddef cimport ptrdiff_t
from libc.stdint cimport int8_t, int32_t, int64_t, uintptr_t
from libc.math cimport NAN
from libc.string cimport memset
from selfplaydrive._sim.common cimport (Sim, Params, Atlas, EGO_DIM, OBJ_DIM, ROAD_DIM,
                                        NUM_COEFFS, SEG_LIGHT)
from selfplaydrive._sim.geometry cimport select_nearest


cdef extern from "rows.h" nogil:
    int spd_simd_init(int want)
    float spd_clip(float v)
    ctypedef struct spd_road_cols:
        const float* mx
        const float* my
        const float* cols
        ptrdiff_t stride
        const int32_t* group
    void spd_road_rows(float* o, const int32_t* idx, int n, const float* recs,
                       const spd_road_cols* rc, float x, float y, float c, float s, float cp,
                       float sp, const int8_t* gstate, int G)
    void spd_object_rows(float* o, const int32_t* cand, int n, const float* table, float x,
                         float y, float c, float s, float cp, float sp, float cv, float sv)

cdef extern from "near.h" nogil:
    int spd_within(const float* bx, const float* by, int nb, float x0, float y0, float r2,
                   int skip, int32_t* out)

def encoder_address():
    """Address of `encode_paper` (an `sd_encoder_fn`, selfplaydrive_abi.h)."""
    return <uintptr_t>encode_paper


def _set_simd(int level):
    """Set this module's SIMD level (selfplaydrive._sim.simd_level); returns the level used."""
    return spd_simd_init(level)


from selfplaydrive._sim import requested_simd
_set_simd(requested_simd())


cdef inline float clip(float v) noexcept nogil:
    """v clipped to [-1, 1] in float (branch-free minss / maxss)."""
    return spd_clip(v)


cdef void encode_paper(const Sim* sim, const Params* prm, const Atlas* atlas, const void* args,
                       int32_t w, float* obs, int32_t stride) noexcept nogil:
    """The paper's encoder (section 2.5) as a component of the ABI (`sd_encoder_fn`): rows of
    world `w` at obs[a * stride]. It uses the world's scratch (cand, cand_d) and the row
    counters obj_rows / road_rows, which the contract allows an encoder to write."""
    observe_world(<Sim*>sim, atlas, prm, w, obs, stride)


cdef void observe_world(Sim* sim, const Atlas* atlas, const Params* prm, int w, float* obs,
                        int64_t stride) noexcept nogil:
    """Write the observation row of every active agent of world `w` (row a at obs[a * stride])."""
    cdef int a, i, nb, own = 0
    cdef float* row
    cdef float* table = sim.cand_d + <int64_t>w * sim.cand_cap
    cdef int32_t* owner = sim.cand + <int64_t>w * sim.cand_cap
    nb = body_table(sim, prm, w, table, owner)
    for a in range(sim.A):
        i = w * sim.A + a
        if sim.active[i]:
            row = obs + a * stride
            write_ego(sim, prm, i, row)
            write_objects(sim, prm, w, i, own, table, nb, row + EGO_DIM)
            write_road(sim, atlas, prm, w, i, row + EGO_DIM + sim.max_obj * OBJ_DIM)
        # body_table packs agents that are active or kept as obstacles first, in slot order
        own += sim.active[i] or sim.obstacle[i]


cdef void write_ego(Sim* sim, const Params* prm, int i, float* o) noexcept nogil:
    cdef int k = sim.wp_idx[i], n = sim.num_wp[i], j
    cdef float c = sim.hcos[i], s = sim.hsin[i], dx0 = 0.0, dy0 = 0.0, dx1 = 0.0, dy1 = 0.0
    if k < n:
        ego_xy(sim, i, k, c, s, &dx0, &dy0)
        ego_xy(sim, i, k + 1 if k + 1 < n else k, c, s, &dx1, &dy1)
    o[0] = clip(sim.width[i] / prm.width_scale)
    o[1] = clip(sim.length[i] / prm.length_scale)
    o[2] = clip(sim.speed[i] / prm.max_speed)
    o[3] = clip(dx0 / prm.wp_scale)
    o[4] = clip(dy0 / prm.wp_scale)
    o[5] = clip(dx1 / prm.wp_scale)
    o[6] = clip(dy1 / prm.wp_scale)
    o[7] = clip(<float>(n - k) / sim.K) if sim.K > 0 else 0.0
    o[8] = clip(sim.lane_s[i] / prm.lateral_scale)
    o[9] = clip(sim.lane_alpha[i] / 3.14159265358979)
    o[10] = sim.lane_valid[i]
    for j in range(NUM_COEFFS):
        o[11 + j] = clip(sim.coeffs[i * NUM_COEFFS + j] / prm.coeff_scale[j])


cdef inline void ego_xy(Sim* sim, int i, int k, float c, float s, float* dx, float* dy) noexcept nogil:
    cdef float ux = sim.waypoints[(i * sim.K + k) * 2] - sim.x[i]
    cdef float uy = sim.waypoints[(i * sim.K + k) * 2 + 1] - sim.y[i]
    dx[0] = c * ux + s * uy
    dy[0] = -s * ux + c * uy


cdef inline int pad4(int n) noexcept nogil:
    return (n + 3) & ~3


def body_scratch(int A, int S, int P):
    """Scratch entries per world that the observation stage writes (body_table: NB 8-float
    records, NB distances, x and y of pad4(NB) floats each; write_objects: NB owners and up
    to NB + 3 candidates), for A agents, S statics and P pedestrians (NB = A + S + P)."""
    cdef int NB = A + S + P
    return max(body_floats(A, S, P), 2 * NB + 3)


cdef int body_floats(int A, int S, int P) noexcept nogil:
    """Floats of cand_d the body table and the object distances use (see body_scratch)."""
    cdef int NB = A + S + P
    return 9 * NB + 2 * pad4(NB)


cdef int body_table(Sim* sim, const Params* prm, int w, float* t, int32_t* owner) noexcept nogil:
    """Pack the observable bodies of world `w` once per step: agents (active or obstacles),
    static vehicles, present pedestrians, in slot order, as 8-float records (x, y, cos, sin,
    vx, vy, length and width scaled and clipped; rows.h) in `t`; owner[k] is the agent slot
    of record k (-1 for other bodies). Then, after the records' slots (NB = A + S + P of
    them), NB floats of distance scratch and the record positions x and y as two arrays of
    pad4(NB) floats, padded with NaN (near.h `spd_within`). Returns the number of records.
    The scratch holds `body_scratch(A, S, P)` floats; `owner` and the candidates of
    write_objects take 2 NB + 3 ints (sim/buffers.py `Dims.of` sizes the scratch)."""
    cdef int k, j, nb = 0, A = sim.A, S = sim.S, P = sim.P, NB = sim.A + sim.S + sim.P
    cdef float* r
    cdef float* bx = t + 9 * NB
    cdef float* by = bx + pad4(NB)
    for k in range(A):
        j = w * A + k
        if sim.active[j] or sim.obstacle[j]:
            r = t + 8 * nb
            r[0] = sim.x[j]; r[1] = sim.y[j]; r[2] = sim.hcos[j]; r[3] = sim.hsin[j]
            r[4] = sim.speed[j] * sim.hcos[j]; r[5] = sim.speed[j] * sim.hsin[j]
            r[6] = clip(sim.length[j] / prm.length_scale); r[7] = clip(sim.width[j] / prm.width_scale)
            owner[nb] = k
            nb += 1
    for k in range(S):
        j = w * S + k
        if sim.st_valid[j]:
            r = t + 8 * nb
            r[0] = sim.st_x[j]; r[1] = sim.st_y[j]; r[2] = sim.st_cos[j]; r[3] = sim.st_sin[j]
            r[4] = 0.0; r[5] = 0.0
            r[6] = clip(sim.st_len[j] / prm.length_scale); r[7] = clip(sim.st_wid[j] / prm.width_scale)
            owner[nb] = -1
            nb += 1
    for k in range(P):
        j = w * P + k
        if sim.ped_valid[j] and sim.ped_here[j]:
            r = t + 8 * nb
            r[0] = sim.ped_x[j]; r[1] = sim.ped_y[j]; r[2] = sim.ped_cos[j]; r[3] = sim.ped_sin[j]
            r[4] = sim.ped_vx[j]; r[5] = sim.ped_vy[j]
            r[6] = clip(sim.ped_len[j] / prm.length_scale); r[7] = clip(sim.ped_wid[j] / prm.width_scale)
            owner[nb] = -1
            nb += 1
    for k in range(pad4(nb)):
        bx[k] = t[8 * k] if k < nb else NAN
        by[k] = t[8 * k + 1] if k < nb else NAN
    return nb


cdef void write_objects(Sim* sim, const Params* prm, int w, int i, int own, const float* table,
                        int nb, float* o) noexcept nogil:
    """The `max_obj` nearest bodies within obs_radius (class not observed, section 2.5), from
    the world's body table (`own`: agent i's record, not observed); ties in distance go to
    the lower table index (slot order)."""
    cdef int NB = sim.A + sim.S + sim.P
    cdef float* cd = <float*>table + 8 * NB        # scratch after the table
    cdef const float* bx = table + 9 * NB
    cdef const float* by = bx + pad4(NB)
    cdef int32_t* cand = sim.cand + <int64_t>w * sim.cand_cap + NB
    cdef int n, k, t
    cdef float x = sim.x[i], y = sim.y[i], R2 = prm.obs_radius * prm.obs_radius, dx, dy
    cdef float c = sim.hcos[i], s = sim.hsin[i]
    cdef float cp = c * prm.inv_pos_scale, sp = s * prm.inv_pos_scale
    cdef float cv = c * prm.inv_max_speed, sv = s * prm.inv_max_speed
    n = spd_within(bx, by, nb, x, y, R2, own, cand)
    if n > sim.max_obj:
        for t in range(n):
            k = cand[t]
            dx = table[8 * k] - x
            dy = table[8 * k + 1] - y
            cd[t] = dx * dx + dy * dy
        select_nearest(cd, cand, n, sim.max_obj)
        n = sim.max_obj
    spd_object_rows(o, cand, n, table, x, y, c, s, cp, sp, cv, sv)
    clear_rows(o, n, &sim.obj_rows[i], OBJ_DIM)


cdef void write_road(Sim* sim, const Atlas* atlas, const Params* prm, int w, int i, float* o) noexcept nogil:
    """The segments chosen by the events gather: midpoint, direction (cos, sin, no trig: the
    directions are precomputed), length, type and traffic-light state, from the packed atlas
    record of each segment, at the atlas positions the gather left in road_idx."""
    cdef int n = sim.road_n[i]
    cdef int32_t* idx = &sim.road_idx[<int64_t>i * sim.max_road]
    # the position scale folded into the rotation: one multiply per coordinate
    cdef float c = sim.hcos[i], s = sim.hsin[i], cp = c * prm.inv_pos_scale, sp = s * prm.inv_pos_scale
    cdef spd_road_cols rc
    rc.mx = atlas.seg_mx
    rc.my = atlas.seg_my
    rc.cols = atlas.seg_cols
    rc.stride = atlas.num_segments + 8
    rc.group = atlas.seg_group
    spd_road_rows(o, idx, n, atlas.seg_rec, &rc, sim.x[i], sim.y[i], c, s, cp, sp,
                  &sim.light_state[w * sim.G], sim.G)
    clear_rows(o, n, &sim.road_rows[i], ROAD_DIM)


cdef inline void clear_rows(float* o, int n, int32_t* written, int dim) noexcept nogil:
    """Zero rows [n, written) of a block whose rows from `written` on are already zero, and
    record n as the new count of written rows."""
    if written[0] > n:
        memset(o + n * dim, 0, (written[0] - n) * dim * sizeof(float))
    written[0] = n
