# cython: language_level=3
"""`World`: binds the env's NumPy buffers to the C structs and runs the step chain over all
worlds in parallel (OpenMP `prange`, one world per iteration, one parallel region per step).
Worlds never share mutable state, so results do not depend on the number of threads."""

import time

import numpy as np

cimport numpy as cnp
from cython.parallel cimport prange
from libc.stdint cimport int8_t, uint8_t, int32_t, int64_t, uint64_t, uintptr_t
from selfplaydrive._sim.common cimport Sim, Params, Atlas, MAX_TERMS, reward_term_fn, encoder_fn
from selfplaydrive._sim.common cimport physics_fn
from selfplaydrive._sim.physics cimport PhysSlot, physics_world
from selfplaydrive._sim.events cimport lights_peds_world, peds_world, collisions_world
from selfplaydrive._sim.road cimport road_world
from selfplaydrive._sim.reward cimport TermSlot, reward_world, finalize_world

# ---- observation encoder component (issue #13) ----
from selfplaydrive._sim.observe cimport encode_paper

ctypedef struct EncoderSlot:
    # The selected observation encoder (internal to the step, not part of the ABI).
    encoder_fn fn            # NULL: a Python encoder fills the rows after the step
    const void* args         # the encoder's own parameters (NULL when none)


cdef inline void encode_world(Sim* sim, const Atlas* atlas, const Params* prm,
                              const EncoderSlot* enc, int w) noexcept nogil:
    """The observation stage of world `w`: one call of the selected encoder (section 2.5)."""
    if enc.fn != NULL:
        enc.fn(sim, prm, atlas, enc.args, w, sim.obs + <int64_t>w * sim.A * sim.obs_dim, sim.obs_dim)
# ---- end observation encoder component ----

cnp.import_array()

STAGES = ("physics", "events", "reward", "observation", "finalize")


cdef void* ptr(dict arrays, str name, object dtype, list keep) except NULL:
    """Data pointer of arrays[name] after checking dtype and C-contiguity."""
    a = arrays[name]
    if not isinstance(a, np.ndarray) or a.dtype != np.dtype(dtype) or not a.flags.c_contiguous:
        raise TypeError(f"buffer {name!r} must be a C-contiguous {np.dtype(dtype)} array, got "
                        f"{getattr(a, 'dtype', type(a))}")
    if a.size == 0:
        a = np.zeros(1, dtype=dtype)  # never dereferenced: counts are 0; keeps the pointer valid
    keep.append(a)
    return cnp.PyArray_DATA(a)


cdef void step_one(Sim* sim, const Atlas* atlas, const Params* prm, const PhysSlot* phys,
                   const TermSlot* slots, const EncoderSlot* enc, int w) noexcept nogil:
    """The whole chain for world `w` (section 2): physics, events, reward, observation."""
    physics_world(sim, prm, phys, w)
    lights_peds_world(sim, prm, w)
    collisions_world(sim, prm, w)
    road_world(sim, atlas, prm, w)
    reward_world(sim, atlas, prm, slots, w)
    encode_world(sim, atlas, prm, enc, w)
    finalize_world(sim, prm, w)


cdef void reset_one(Sim* sim, const Atlas* atlas, const Params* prm, const EncoderSlot* enc,
                    int w) noexcept nogil:
    """After packing a new scenario into world `w`: place pedestrians, gather road data, observe."""
    cdef int a, i, k
    peds_world(sim, prm, w)
    for k in range(w * sim.P, (w + 1) * sim.P):
        sim.ped_px[k] = sim.ped_x[k]
        sim.ped_py[k] = sim.ped_y[k]
    for a in range(sim.A):
        sim.road_r[w * sim.A + a] = -1.0  # new positions: the road gather starts without a hint
    road_world(sim, atlas, prm, w)
    for a in range(sim.A):
        i = w * sim.A + a
        sim.events[i] = 0  # events found while placing the scenario earn nothing
    # physics components: a model's own per-agent state starts at 0 at spawn (abi.h)
    for k in range(w * sim.A * sim.phys_dim, (w + 1) * sim.A * sim.phys_dim):
        sim.phys_state[k] = 0.0
    # reward terms with state (abi.h): their per-agent memory likewise starts at 0 at spawn
    for k in range(w * sim.A * sim.term_state_dim, (w + 1) * sim.A * sim.term_state_dim):
        sim.term_state[k] = 0.0
    encode_world(sim, atlas, prm, enc, w)


cdef class World:
    """Owns pointers into the env's buffers and steps all worlds.

    Args:
        dims: The `Dims` fields (the dimension rows of the schema, sim/schema.py).
        state: Buffers named as the `Sim` fields (sim/buffers.py allocates them).
        layout: (fields, size) of `sd_sim` from the schema (sim/schema.py `struct_layout`):
            per field its name, byte offset and buffer dtype (None: a dimension of `dims`).
        atlas: Concatenated map arrays named as the `Atlas` fields (sim/atlas.py).
        params: Scalars named as the `Params` fields plus accel_table, steer_table, coeff_scale.
        terms: One (address, args, weight, native) per column of the `terms` buffer, in column
            order: the address of an `sd_reward_term_fn` (selfplaydrive_abi.h) or 0 for no call
            (a Python column, or one a group written earlier fills), its float32 parameters
            (or None), its weight, and 1 when the step fills it (0: Python, after the step).
            rewards/components.py `LinearReward.plan` makes them and checks the addresses.
        encoder: (address, args) of the observation encoder: the address of an `sd_encoder_fn`
            (0: none, a Python encoder fills the rows after the step) and its parameters as a
            C-contiguous NumPy array passed as `const void*` (or None). obs/encoders.py
            `KernelEncoder.plan` makes it. None: the paper's encoder.
        physics: (address, args) of the physics model: the address of an `sd_physics_fn`
            (selfplaydrive_abi.h) or 0 for a model stepped in Python before the step, and its
            float32 parameters (or None). physics/components.py makes it.
    """

    cdef Sim sim
    cdef Atlas atlas
    cdef Params prm
    cdef TermSlot slots[MAX_TERMS]
    cdef EncoderSlot enc
    cdef PhysSlot phys
    cdef list keep
    cdef public dict timings

    def __init__(self, dict dims, dict state, tuple layout, dict atlas, dict params, list terms,
                 tuple physics, encoder=None):
        self.keep = []
        self.timings = {name: 0.0 for name in STAGES + ("reset",)}
        self._bind_state(dims, state, layout)
        self._bind_atlas(atlas)
        self._bind_params(params)
        self._bind_terms(terms, state)
        self._bind_physics(physics, state)
        self._bind_encoder(encoder)

    def _bind_encoder(self, encoder):
        """Select the observation encoder component (one function pointer and its args)."""
        cdef uintptr_t address
        if encoder is None:  # the paper's encoder (section 2.5)
            self.enc.fn = encode_paper
            self.enc.args = NULL
            return
        address, args = encoder
        self.enc.fn = <encoder_fn>address
        self.enc.args = NULL
        if args is not None:
            if not isinstance(args, np.ndarray) or not args.flags.c_contiguous or args.nbytes == 0:
                raise TypeError(f"encoder args: expected a non-empty C-contiguous array, got {args!r}")
            self.keep.append(args)
            self.enc.args = <const void*>cnp.PyArray_DATA(args)

    def _bind_physics(self, tuple physics, dict s):
        """The physics model's slot: its function (NULL: stepped in Python) and parameters."""
        cdef uintptr_t address
        address, args = physics
        N = self.sim.W * self.sim.A
        for name, shape in (("act_i", (N, self.sim.act_dim)), ("act_f", (N, self.sim.act_dim)),
                            ("phys_state", (N, self.sim.phys_dim)),
                            ("term_state", (N, self.sim.term_state_dim))):
            if s[name].shape != shape:
                raise ValueError(f"buffer {name}: expected shape {shape}, got {s[name].shape}")
        self.phys.fn = <physics_fn>address
        self.phys.args = NULL
        if args is not None:
            self.phys.args = <const float*>ptr({"args": args}, "args", np.float32, self.keep)

    def _bind_terms(self, list terms, dict s):
        """Fill the component table of the reward stage (one slot per column)."""
        cdef int k, M = len(terms)
        cdef uintptr_t address
        if not 1 <= M <= MAX_TERMS or M != self.sim.num_terms:
            raise ValueError(f"terms: expected {self.sim.num_terms} columns (1 to {MAX_TERMS}), got {M}")
        N = self.sim.W * self.sim.A
        if s["terms"].shape != (N, M) or s["term_sum"].shape != (self.sim.W, M):
            raise ValueError(f"buffers terms / term_sum: expected ({N}, {M}) and ({self.sim.W}, {M}), got "
                             f"{s['terms'].shape} and {s['term_sum'].shape}")
        for k in range(M):
            address, args, weight, native = terms[k]
            self.slots[k].fn = <reward_term_fn>address
            self.slots[k].native = native
            self.slots[k].args = NULL
            if args is not None:
                self.slots[k].args = <const float*>ptr({"args": args}, "args", np.float32, self.keep)
            self.slots[k].weight = weight

    def _bind_state(self, dict dims, dict s, tuple layout):
        """Fill `sd_sim` from the schema (sim/schema.py `struct_layout`): each dimension from
        `dims`, each pointer from the buffer of its name (dtype and C-contiguity checked), at
        the byte offset the schema computed from the field order and C types (the offsets are
        those of the compiled struct: same order and types, tests/sim/test_schema.py)."""
        cdef char* base = <char*>&self.sim
        cdef Py_ssize_t offset
        fields, size = layout
        if size != sizeof(Sim):
            raise ValueError(f"state layout: expected sizeof(sd_sim) = {sizeof(Sim)} bytes (the compiled "
                             f"struct), got {size}: the schema table and selfplaydrive_abi.h differ")
        for name, offset, dtype in fields:
            if not 0 <= offset <= size - sizeof(void*):
                raise ValueError(f"state layout: field {name!r} at byte {offset}, outside sd_sim")
            if dtype is None:
                (<int*>(base + offset))[0] = <int>dims[name]
            else:
                (<void**>(base + offset))[0] = ptr(s, name, dtype, self.keep)

    def _bind_atlas(self, dict a):
        cdef list k = self.keep
        f4, i1, i4, i8 = np.float32, np.int8, np.int32, np.int64
        self.atlas.num_maps = len(a["grid_cell"])
        ns = len(a["seg_rec"])
        self.atlas.num_segments = ns
        for name, shape in (("seg_rec", (ns, 8)), ("seg_cols", (4, ns + 8)), ("seg_mx", (ns + 8,)),
                            ("seg_my", (ns + 8,)), ("seg_id", (ns + 8,)), ("seg_group", (ns + 8,))):
            if a[name].shape != shape:
                raise ValueError(f"atlas {name}: expected shape {shape}, got {a[name].shape}")
        self.atlas.seg_group = <int32_t*>ptr(a, "seg_group", i4, k)
        self.atlas.seg_mx = <float*>ptr(a, "seg_mx", f4, k); self.atlas.seg_my = <float*>ptr(a, "seg_my", f4, k)
        self.atlas.seg_rec = <float*>ptr(a, "seg_rec", f4, k)
        self.atlas.seg_cols = <float*>ptr(a, "seg_cols", f4, k)
        self.atlas.seg_id = <int32_t*>ptr(a, "seg_id", i4, k)
        self.atlas.grid_origin = <float*>ptr(a, "grid_origin", f4, k); self.atlas.grid_cell = <float*>ptr(a, "grid_cell", f4, k)
        self.atlas.grid_nx = <int32_t*>ptr(a, "grid_nx", i4, k); self.atlas.grid_ny = <int32_t*>ptr(a, "grid_ny", i4, k)
        self.atlas.cell_base = <int64_t*>ptr(a, "cell_base", i8, k)
        self.atlas.cell_offsets = <int32_t*>ptr(a, "cell_offsets", i4, k)
        self.atlas.max_seg_len = <float*>ptr(a, "max_seg_len", f4, k)

    def _bind_params(self, dict p):
        cdef list k = self.keep
        self.prm.dt = p["dt"]; self.prm.physics = p["physics"]; self.prm.wheelbase_ratio = p["wheelbase_ratio"]
        self.prm.gravity = p["gravity"]; self.prm.max_speed = p["max_speed"]; self.prm.discrete = p["discrete"]
        self.prm.accel_table = <float*>ptr(p, "accel_table", np.float32, k)
        self.prm.steer_table = <float*>ptr(p, "steer_table", np.float32, k)
        self.prm.comfort_limit = p["comfort_limit"]; self.prm.obs_radius = p["obs_radius"]
        self.prm.lane_radius = p["lane_radius"]; self.prm.terminate_threshold = p["terminate_threshold"]
        self.prm.obstacle_mode = p["obstacle_mode"]; self.prm.velocity_reward = p["velocity_reward"]
        self.prm.velocity_min = p["velocity_min"]; self.prm.waypoint_reward = p["waypoint_reward"]
        self.prm.center_max_angle = p["center_max_angle"]; self.prm.light_min = p["light_min"]
        self.prm.light_max = p["light_max"]; self.prm.ped_vanish = p["ped_vanish"]
        self.prm.pos_scale = p["pos_scale"]; self.prm.wp_scale = p["wp_scale"]
        self.prm.length_scale = p["length_scale"]; self.prm.width_scale = p["width_scale"]
        self.prm.lateral_scale = p["lateral_scale"]
        self.prm.coeff_scale = <float*>ptr(p, "coeff_scale", np.float32, k)
        self.prm.max_substeps = p["max_substeps"]
        self.prm.inv_pos_scale = 1.0 / self.prm.pos_scale; self.prm.inv_wp_scale = 1.0 / self.prm.wp_scale
        self.prm.inv_length_scale = 1.0 / self.prm.length_scale
        self.prm.inv_width_scale = 1.0 / self.prm.width_scale
        self.prm.inv_lateral_scale = 1.0 / self.prm.lateral_scale
        self.prm.inv_max_speed = 1.0 / self.prm.max_speed
        self.prm.collision_speed_gain = p["collision_speed_gain"]; self.prm.center_bonus = p["center_bonus"]
        self.prm.center_bonus_offset = p["center_bonus_offset"]; self.prm.align_bonus = p["align_bonus"]

    def set_term_weight(self, int k, double weight):
        """Set the weight of column k of the reward from the next step on (a schedule of term
        weights between rollouts, `VecEnv.set_term_weight`); never during a step."""
        if not 0 <= k < self.sim.num_terms:
            raise IndexError(f"set_term_weight: column {k} is outside 0..{self.sim.num_terms - 1}")
        if not np.isfinite(weight):
            raise ValueError(f"set_term_weight: column {k}: expected a finite weight, got {weight!r}")
        self.slots[k].weight = <float>weight

    def step(self, int num_threads=1, bint profile=False, int chunk=0):
        """Advance every world one step; with `profile`, stage by stage with timings. `chunk`:
        worlds handed to a thread at a time (0: 2 when there are at least 4 per thread, else 1;
        two neighbouring worlds' per-slot bytes fill one cache line)."""
        cdef int w, W = self.sim.W
        if chunk <= 0:
            chunk = 2 if W >= 4 * num_threads else 1
        if profile:
            self._step_profiled(num_threads)
            return
        with nogil:
            # one parallel region per step; worlds handed out a few at a time, so a thread that
            # the OS deschedules (shared machine) does not hold the others back, while
            # neighbouring worlds (whose per-slot bytes share cache lines) mostly stay on one
            # thread. Results do not depend on which thread steps a world.
            for w in prange(W, num_threads=num_threads, schedule="dynamic", chunksize=chunk):
                step_one(&self.sim, &self.atlas, &self.prm, &self.phys, self.slots, &self.enc, w)

    def _step_profiled(self, int num_threads):
        cdef int w, W = self.sim.W
        t0 = time.perf_counter()
        with nogil:
            for w in prange(W, num_threads=num_threads, schedule="static"):
                physics_world(&self.sim, &self.prm, &self.phys, w)
        t1 = time.perf_counter()
        with nogil:
            for w in prange(W, num_threads=num_threads, schedule="static"):
                lights_peds_world(&self.sim, &self.prm, w)
                collisions_world(&self.sim, &self.prm, w)
                road_world(&self.sim, &self.atlas, &self.prm, w)
        t2 = time.perf_counter()
        with nogil:
            for w in prange(W, num_threads=num_threads, schedule="static"):
                reward_world(&self.sim, &self.atlas, &self.prm, self.slots, w)
        t3 = time.perf_counter()
        with nogil:
            for w in prange(W, num_threads=num_threads, schedule="static"):
                encode_world(&self.sim, &self.atlas, &self.prm, &self.enc, w)
        t4 = time.perf_counter()
        with nogil:
            for w in prange(W, num_threads=num_threads, schedule="static"):
                finalize_world(&self.sim, &self.prm, w)
        t5 = time.perf_counter()
        for name, dt in zip(STAGES, (t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4)):
            self.timings[name] += dt

    def encode(self, int num_threads=1):
        """Run only the observation encoder on every world, as the step does (the encoder
        checker, selfplaydrive/testing/check_encoder.py, compares the buffers around it)."""
        cdef int w, W = self.sim.W
        with nogil:
            for w in prange(W, num_threads=num_threads, schedule="static"):
                encode_world(&self.sim, &self.atlas, &self.prm, &self.enc, w)

    def physics_stage(self, int num_threads=1):
        """Run only the physics stage of every world (selfplaydrive.testing.check_physics)."""
        cdef int w, W = self.sim.W
        with nogil:
            for w in prange(W, num_threads=num_threads, schedule="static"):
                physics_world(&self.sim, &self.prm, &self.phys, w)

    def after_reset(self, cnp.ndarray worlds, int num_threads=1):
        """Finish the reset of the listed worlds (int32 indices) after their scenario was packed."""
        cdef const int32_t[::1] ws = np.ascontiguousarray(worlds, dtype=np.int32)
        cdef int k, n = ws.shape[0]
        for k in range(n):
            if not 0 <= ws[k] < self.sim.W:
                raise IndexError(f"world index {ws[k]} out of range [0, {self.sim.W})")
        with nogil:
            for k in prange(n, num_threads=num_threads, schedule="static"):
                reset_one(&self.sim, &self.atlas, &self.prm, &self.enc, ws[k])


ctypedef fused action_int:
    int32_t
    int64_t


def copy_discrete(const action_int[:, ::1] a, int32_t[:, ::1] out, int n_acc, int n_steer):
    """Range-check (N, 2) action indices and copy them into `out` (int32) in one pass, for the
    common dtypes (int32, int64; others take the NumPy path in sim/actions.py). Returns -1 when
    every index is valid, else the row of the first bad one (then nothing is copied, and the
    caller's NumPy check raises the error that names it)."""
    cdef Py_ssize_t i, bad = -1, n = a.shape[0]
    if a.shape[1] != 2 or out.shape[0] != n or out.shape[1] != 2:
        raise ValueError(f"copy_discrete: expected (N, 2) arrays, got {a.shape[0]}x{a.shape[1]} "
                         f"and {out.shape[0]}x{out.shape[1]}")
    with nogil:
        for i in range(n):
            if not (0 <= a[i, 0] < n_acc and 0 <= a[i, 1] < n_steer):
                bad = i
                break
        if bad < 0:
            for i in range(n):
                out[i, 0] = <int32_t>a[i, 0]
                out[i, 1] = <int32_t>a[i, 1]
    return bad
