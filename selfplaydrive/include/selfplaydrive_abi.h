/* selfplaydrive component ABI: the typed view of the simulator state that kernels and
 * plug-in components read (paper section 2), and the signatures of a reward-term component
 * (section 2.3) and of an observation encoder (section 2.5). docs/components.md "Write a reward
 * term" and "Write an observation encoder" explain the contracts.
 *
 * Include with the folder of `selfplaydrive.get_include()` on the include path; Cython code
 * cimports the same declarations from `selfplaydrive_abi.pxd` in that folder.
 *
 * Arrays: every pointer addresses a C-contiguous array owned by the Python side
 * (selfplaydrive/sim/buffers.py for the state, sim/atlas.py for the read-only map). Agent arrays
 * are indexed by the flat agent index i = w * A + a (world w, slot a); static, pedestrian and
 * light arrays likewise by w * S + k, w * P + k and w * G + g. Units: [m], [m/s], [m/s^2], [rad],
 * [s]; world frame unless stated.
 *
 * Schema: the fields of sd_sim are the rows of the table in selfplaydrive/sim/schema.py (name,
 * C type, shape, unit, owner), which allocates the buffers and fills this struct; a test
 * compares the two field by field. A new field is a row there and a line here and in the .pxd.
 *
 * Compatibility: SELFPLAYDRIVE_ABI_VERSION changes whenever a field is removed, reordered or
 * retyped (fields are only ever appended otherwise); `selfplaydrive.components.ABI_VERSION`
 * gives the version a library build expects.
 */
#ifndef SELFPLAYDRIVE_ABI_H
#define SELFPLAYDRIVE_ABI_H

#include <stdint.h>

#define SELFPLAYDRIVE_ABI_VERSION 1

/* Road segment types: selfplaydrive.maps.roadmap.SegmentType. */
enum {
    SD_SEG_LANE = 0,
    SD_SEG_EDGE = 1,
    SD_SEG_STOP = 2,
    SD_SEG_LIGHT = 3,
    SD_SEG_CROSSWALK = 4
};

/* Traffic-light states (section 2.2). */
enum { SD_LIGHT_OFF = 0, SD_LIGHT_RED = 1, SD_LIGHT_YELLOW = 2, SD_LIGHT_GREEN = 3 };

/* Per-step event bits of an agent (`sd_sim.events`); the same bits mark `sd_sim.ever`. */
enum {
    SD_EV_COLLIDE = 1,    /* box overlaps another vehicle (agent, static or obstacle) */
    SD_EV_PED = 2,        /* box overlaps a pedestrian */
    SD_EV_OFFROAD = 4,    /* box touches a road-edge segment */
    SD_EV_RED = 8,        /* box touches (or the centre crossed) a red traffic-light line */
    SD_EV_WAYPOINT = 16,  /* current waypoint reached this step */
    SD_EV_COMFORT = 32    /* |a_long| or |a_lat| above the comfort limit */
};

/* The paper's eight reward terms (section 2.3), in the order of selfplaydrive.rewards.TERM_NAMES. */
enum {
    SD_T_WAYPOINT = 0,
    SD_T_COLLISION = 1,
    SD_T_OFFROAD = 2,
    SD_T_RED = 3,
    SD_T_COMFORT = 4,
    SD_T_CENTER = 5,
    SD_T_ALIGN = 6,
    SD_T_VELOCITY = 7,
    SD_NUM_PAPER_TERMS = 8,
    SD_MAX_TERMS = 64     /* most reward columns one env may select */
};

/* Columns of `sd_sim.coeffs`, the per-agent reward coefficients (scenario.types.COEFF_NAMES). */
enum {
    SD_C_RADIUS = 0,      /* D [m], waypoint radius */
    SD_C_COLLISION = 1,
    SD_C_OFFROAD = 2,
    SD_C_RED = 3,
    SD_C_COMFORT = 4,
    SD_C_CENTER = 5,
    SD_C_BIAS = 6,        /* B [m], lane-centre bias */
    SD_C_ALIGN = 7,
    SD_NUM_COEFFS = 8
};

/* Columns of `sd_sim.hidden` (scenario.types.HIDDEN_PARAMS). */
enum { SD_H_FRICTION = 0, SD_H_ACCEL_GAIN = 1, SD_H_STEER_GAIN = 2 };

/* Columns of `sd_sim.ev_count`, event counts per world over the episode. */
enum {
    SD_S_COLLIDE = 0,
    SD_S_PED = 1,
    SD_S_OFFROAD = 2,
    SD_S_RED = 3,
    SD_S_WAYPOINT = 4,
    SD_S_COMFORT = 5,
    SD_S_TERMINATED = 6,
    SD_S_TRUNCATED = 7,
    SD_NUM_STATS = 8
};

/* Physics models (section 2.6): the value of `sd_params.physics`, for listings only (the step
 * calls the selected model through its `sd_physics_fn`; no kernel branches on this). */
enum { SD_PHYS_BICYCLE = 0, SD_PHYS_FRICTION = 1, SD_PHYS_EXTERNAL = 2, SD_PHYS_COMPONENT = 3 };

/* Observation block sizes (obs/layout): features of the ego, per object, per road segment. */
enum { SD_EGO_DIM = 19, SD_OBJ_DIM = 9, SD_ROAD_DIM = 8 };

typedef struct sd_atlas {
                                  /* Read-only road data of every map of the env, concatenated (sim/atlas.py). Segment arrays */
                                  /* are in atlas order (per map, sorted by grid cell); seg_id gives the global segment index */
                                  /* of an atlas position (`Sim.road_idx` holds atlas positions). */
    int num_maps;                 /* number of maps */
    int num_segments;             /* Ns, segments of all maps */
    const float* seg_mx;          /* (Ns + 8,) [m] midpoint x (the records' lane 0 again, for contiguous */
                                  /* scans; the SIMD kernels read whole vectors, hence the padding) */
    const float* seg_my;          /* (Ns + 8,) [m] midpoint y */
    const int32_t* seg_id;        /* (Ns + 8,) global segment index of each atlas position */
    const float* seg_rec;         /* (Ns, 8) packed record of the road events and rows: mid x, mid */
                                  /* y, dir x, dir y, min(length / length_scale, 1), type / 4, */
                                  /* length [m], signal group (-1: none) (_sim/rows.h, road.pyx) */
    const float* seg_cols;        /* (4, Ns + 8) record lanes 2-5 as columns: dir x, dir y, scaled */
                                  /* length, type / 4 (rows of consecutive segments, _sim/rows.h) */
    const int32_t* seg_group;     /* (Ns + 8,) signal group of a traffic-light segment, -1 otherwise */
    const float* grid_origin;     /* (M, 2) [m] lower-left corner of each map's grid */
    const float* grid_cell;       /* (M,) [m] cell edge of each map's grid */
    const int32_t* grid_nx;       /* (M,) cells along x */
    const int32_t* grid_ny;       /* (M,) cells along y */
    const int64_t* cell_base;     /* (M,) offset of map m's first cell in cell_offsets */
    const int32_t* cell_offsets;  /* (sum nx*ny + M,) CSR: cell c of map m holds atlas positions */
                                  /* [cell_offsets[cell_base[m] + c], cell_offsets[... + c + 1]) */
    const float* max_seg_len;     /* (M,) [m] longest segment of each map */
} sd_atlas;

typedef struct sd_params {
                                  /* Constants of one env (sim/params.py `SimParams`); never changed while stepping. */
    float dt;                     /* [s] step length (0.1, section 2) */
    int physics;                  /* SD_PHYS_* kernel */
    float wheelbase_ratio;        /* wheelbase / box length of the bicycle model */
    float gravity;                /* [m/s^2] g of the friction limit (9.81) */
    float max_speed;              /* [m/s] speed clamp (also the observation scale of speeds) */
    int discrete;                 /* 1: actions are table indices, 0: continuous values */
    const float* accel_table;     /* (n_accel,) [m/s^2] discrete acceleration values (action */
                                  /* column 0's values; a model may give them another meaning) */
    const float* steer_table;     /* (n_steer,) [rad] discrete steering angles (column 1's values) */
    float comfort_limit;          /* [m/s^2] comfort threshold on |a_long| and |a_lat| (3) */
    float obs_radius;             /* [m] objects and road segments are observed within this (100) */
    float lane_radius;            /* [m] lane association searches centerlines within this */
    float terminate_threshold;    /* C_collision / C_offroad at or above which an event ends the agent (0.5) */
    int obstacle_mode;            /* 1: a terminated vehicle stays as a static obstacle, 0: removed */
    float velocity_reward;        /* reward per step at max(cos alpha, 0) = 1 (2.5e-4) */
    float velocity_min;           /* [m/s] minimum speed for the velocity reward (2.5) */
    float waypoint_reward;        /* reward per reached waypoint (0.25) */
    float center_max_angle;       /* [rad] centre reward only when |alpha| is below this (60 deg) */
    float light_min;              /* [s] shortest traffic-light state duration (0.5) */
    float light_max;              /* [s] longest duration (10) */
    int ped_vanish;               /* 1: a pedestrian at the end of its path disappears, 0: stands */
    float pos_scale;              /* [m] observation scale of object and road positions (= obs_radius) */
    float wp_scale;               /* [m] observation scale of waypoint offsets */
    float length_scale;           /* [m] observation scale of box and segment lengths */
    float width_scale;            /* [m] observation scale of box widths */
    float lateral_scale;          /* [m] observation scale of the lane offset s */
    const float* coeff_scale;     /* (SD_NUM_COEFFS,) observation scale of each reward coefficient */
    int max_substeps;             /* cap on collision sub-steps per pair (anti-tunnelling) */
                                  /* reciprocals of the scales above (multiplications instead of divisions in inner loops) */
    float inv_pos_scale;
    float inv_wp_scale;
    float inv_length_scale;
    float inv_width_scale;
    float inv_lateral_scale;
    float inv_max_speed;
                                  /* shapes of the reward terms (section 2.3; the reward group's keys, docs/rewards.md) */
    double collision_speed_gain;  /* [s/m] collision and road-edge penalties scale with (1 + gain v) (0.1) */
    double center_bonus;          /* height of the centre term's bonus center_bonus / exp(|B - s| - offset) (0.05) */
    float center_bonus_offset;    /* [m] offset of that bonus (0.5) */
    double align_bonus;           /* align term's bonus align_bonus (1 - |alpha| / (pi / 2)) (0.0025) */
} sd_params;

typedef struct sd_sim {
                                  /* Mutable state of all worlds (sim/vec_env.py owns the arrays). */
    int W;                        /* worlds */
    int A;                        /* agent slots per world */
    int S;                        /* static vehicle slots per world */
    int P;                        /* pedestrian slots per world */
    int K;                        /* waypoint slots per agent */
    int T;                        /* points per pedestrian path */
    int G;                        /* signal groups per world (max over maps, >= 1) */
    int max_obj;                  /* observed objects per agent (63) */
    int max_road;                 /* observed road segments per agent (200) */
    int cand_cap;                 /* scratch capacity per world for road candidates */
    int obs_dim;                  /* floats per observation row */
    int num_terms;                /* M, columns of `terms` and `term_sum` (the selected reward terms) */
                                  /* agents (W * A) */
    float* x;                     /* [m] box centre x */
    float* y;                     /* [m] box centre y */
    float* heading;               /* [rad] in (-pi, pi] */
    float* hcos;                  /* cos(heading), cached by physics */
    float* hsin;                  /* sin(heading) */
    float* speed;                 /* [m/s] >= 0, along the direction of travel */
    float* px;                    /* [m] centre x before the last physics step */
    float* py;                    /* [m] centre y before the last physics step */
    float* pheading;              /* [rad] heading before the last physics step */
    float* length;                /* [m] box length */
    float* width;                 /* [m] box width */
    float* a_long;                /* [m/s^2] longitudinal acceleration applied in the last step */
    float* a_lat;                 /* [m/s^2] lateral acceleration applied in the last step */
    float* coeffs;                /* (N, SD_NUM_COEFFS) reward coefficients (observed) */
    float* hidden;                /* (N, 3) friction mu, accel gain, steer gain (never observed) */
    float* waypoints;             /* (N, K, 2) [m] route waypoints */
    int32_t* num_wp;              /* (N,) valid waypoints */
    int32_t* wp_idx;              /* (N,) index of the current waypoint (num_wp when all reached) */
    uint8_t* active;              /* (N,) slot holds an agent that is still playing */
    uint8_t* obstacle;            /* (N,) ended agent left on the road as a static obstacle */
    float* lane_s;                /* [m] signed lateral offset from the associated centerline, + right */
    float* lane_alpha;            /* [rad] heading minus lane direction, in (-pi, pi], + = rotated left */
    uint8_t* lane_valid;          /* 1 when a centerline was found within lane_radius */
    uint8_t* events;              /* SD_EV_* bits of the last step */
    uint8_t* ever;                /* SD_EV_* bits accumulated over the episode */
    int32_t* road_idx;            /* (N, max_road) atlas positions of the road segments observed */
    int32_t* road_n;              /* (N,) number of valid entries in road_idx */
    int32_t* obj_rows;            /* (N,) object rows written at the slot's last observation: the */
                                  /* rows after them are zero (observe.pyx clears only what changed) */
    int32_t* road_rows;           /* (N,) the same for the road rows */
    float* road_r;                /* (N,) [m] distance of the max_road-th nearest segment at the last */
                                  /* gather (obs_radius when fewer lie within it); < 0: no gather yet */
    float* road_x;                /* (N,) [m] position of that gather (the bound holds wherever the */
    float* road_y;                /* agent moved since, teleports included) */
    int32_t* act_i;               /* (N, act_dim) discrete action indices (accel, steer) */
    float* act_f;                 /* (N, act_dim) continuous actions [m/s^2], [rad] */
    float* reward;                /* (N,) summed reward of the last step */
    float* terms;                 /* (N, num_terms) per-term reward of the last step */
    uint8_t* term;                /* (N,) terminated in the last step */
    uint8_t* trunc;               /* (N,) truncated (time limit) in the last step */
    float* obs;                   /* (N, obs_dim) observations */
    float* final_obs;             /* (N, obs_dim) observation at the end of an agent's episode */
                                  /* static vehicles (W * S) */
    float* st_x;                  /* [m] */
    float* st_y;                  /* [m] */
    float* st_cos;                /* cos(heading) */
    float* st_sin;                /* sin(heading) */
    float* st_len;                /* [m] */
    float* st_wid;                /* [m] */
    uint8_t* st_valid;            /* slot holds a static vehicle */
                                  /* pedestrians (W * P) */
    float* ped_path;              /* (W*P, T, 2) [m] path polyline */
    int32_t* ped_np;              /* valid path points */
    float* ped_speed;             /* [m/s] walking speed */
    float* ped_start;             /* [s] start time */
    float* ped_len;               /* [m] box length */
    float* ped_wid;               /* [m] box width */
    uint8_t* ped_valid;           /* slot holds a pedestrian */
    uint8_t* ped_here;            /* pedestrian is present (0 after vanishing at the path end) */
    float* ped_x;                 /* [m] current centre */
    float* ped_y;                 /* [m] */
    float* ped_px;                /* [m] centre before the last step */
    float* ped_py;                /* [m] */
    float* ped_cos;               /* cos(heading) */
    float* ped_sin;               /* sin(heading) */
    float* ped_vx;                /* [m/s] velocity, world frame */
    float* ped_vy;                /* [m/s] */
                                  /* traffic lights (W * G) */
    int8_t* light_state;          /* SD_LIGHT_* per signal group */
    float* light_time;            /* [s] until the group's next change */
                                  /* worlds (W) */
    int32_t* map_id;              /* map of the world in the atlas */
    int32_t* step;                /* steps taken in the current episode */
    int32_t* max_steps;           /* episode length in steps */
    uint8_t* lights_on;           /* 0 in the episodes where every light stays off */
    uint8_t* done;                /* world ended in the last step (autoreset follows) */
    uint64_t* rng_key;            /* counter-based RNG key of the world */
    uint64_t* rng_ctr;            /* counter-based RNG counter of the world */
    double* term_sum;             /* (W, num_terms) per-term reward sums over the episode */
    int64_t* ev_count;            /* (W, NUM_STATS) event counts over the episode */
    double* dist;                 /* [m] distance driven by all agents of the episode */
    int32_t* cand;                /* (W, cand_cap) scratch: candidate indices */
    float* cand_d;                /* (W, cand_cap) scratch: candidate squared distances [m^2] */
                                  /* --- physics-model components (appended, ABI 1; sd_physics_fn) --- */
    int act_dim;                  /* D, columns of act_i and act_f: the model's action dimensions */
                                  /* (2 for the bicycle models' (accel, steer)) */
    int phys_dim;                 /* floats of model-owned state per agent slot (0: none) */
    float* phys_state;            /* (N, phys_dim) state the physics model owns; 0 at spawn */
                                  /* --- reward-term state (appended, ABI 1; sd_reward_term_fn) --- */
    int term_state_dim;           /* floats of reward-term state per agent slot: the sum of the */
                                  /* selected terms' declared widths (0: none) */
    float* term_state;            /* (N, term_state_dim) per-agent memory of the reward terms; each */
                                  /* stateful term owns its columns [offset, offset + width), the */
                                  /* offset given in its args; 0 at spawn */
} sd_sim;
/* A reward-term component (section 2.3): computes one term for every active agent slot of
 * world `w` and writes it to out[a * stride] for slot a in [0, sim->A). It reads the state
 * through `sim`, `prm` and `atlas` and writes `out` and its own state columns only: a term that
 * declares a state width (`KernelTerm(state_dim=...)`) owns the columns [offset, offset + width)
 * of sim->term_state (row i = w * A + a, sim->term_state_dim floats per row, zeroed at spawn),
 * where offset = (int)args[0], set by the env when it lays out the selected terms' state
 * (docs/components.md "Reward terms with state"). Rows of inactive slots
 * (sim->active[w * sim->A + a] == 0) may be left unwritten: the step zeroes them. `args` holds
 * the term's own parameters (the floats given to `KernelTerm(args=...)`, NULL when none). The
 * step multiplies the value by the term's weight afterwards. Called once per world inside the
 * parallel step, without the GIL, possibly from several threads at once for different worlds:
 * no global state, no allocation, no Python. */
typedef void (*sd_reward_term_fn)(const sd_sim* sim, const sd_params* prm, const sd_atlas* atlas,
                                  const float* args, int32_t w, float* out, int32_t stride);

/* ---- observation encoders (issue #13; docs/components.md "Write an observation encoder") ----
 * Appended in ABI version 1 (no field of the structs above changed, so the version stays).
 *
 * An observation encoder (section 2.5) writes the observation row of every active agent slot of
 * world `w`: row a (slot a in [0, sim->A)) is obs[a * stride .. a * stride + sim->obs_dim), with
 * `obs` the world's first row (&sim->obs[w * A * obs_dim]) and `stride` = sim->obs_dim. Rows of
 * inactive slots (sim->active[w * A + a] == 0) must be left alone (they keep the agent's last
 * observation, which final_obs copies). It reads the state through `sim` (including the road
 * gather of the events stage: road_idx[i, :road_n[i]], atlas positions of the max_road nearest
 * segments within obs_radius), the constants through `prm` (obs_radius = pos_scale, the
 * feature scales), the map through `atlas`, and its own parameters through `args` (whatever
 * the encoder's Python object packed: `KernelEncoder(args=...)`, NULL when none). Besides its
 * rows it may write only the world's scratch, cand[w * cand_cap ..] and cand_d[w * cand_cap ..]
 * (contents undefined on entry and after the call), and the per-slot row counters obj_rows and
 * road_rows of the world's slots (the paper encoder's record of which rows hold objects and
 * segments, so it clears only the padding that changed). Called once per world inside the
 * parallel step and after a reset, without the GIL, possibly from several threads for
 * different worlds: no global state, no allocation, no Python. */
typedef void (*sd_encoder_fn)(const sd_sim* sim, const sd_params* prm, const sd_atlas* atlas,
                              const void* args, int32_t w, float* obs, int32_t stride);

/* ---- physics-model components (section 2.6; docs/components.md "Write a physics model") ----
 * A physics model advances every active agent slot of world `w` by one step prm->dt from its
 * action: act_i[i * act_dim + k] (discrete, prm->discrete == 1: indices into the model's value
 * tables prm->accel_table / prm->steer_table) or act_f[i * act_dim + k] (continuous), i = w * A + a.
 * Before the call the step has copied x, y, heading into px, py, pheading and zeroed a_long,
 * a_lat of every slot of the world (a slot the model leaves alone stands still). The model writes
 * only x, y, heading (wrapped to (-pi, pi]), hcos, hsin (cos / sin of the new heading), speed
 * (>= 0, <= prm->max_speed), a_long, a_lat of active slots (px, py, pheading when it moves a car
 * along another path than the straight sweep), and its own per-agent state: `state` points at
 * the world's rows of `sim->phys_state`, (A, phys_dim) floats, zeroed when the world is reset
 * (NULL when the model declares none). After the call the step adds speed * dt of every active
 * slot to the world's distance. `args` holds the model's own parameters (float32, NULL when
 * none). Called once per world inside the parallel step, without the GIL, possibly from several
 * threads at once for different worlds: no global state, no allocation, no Python. */
typedef void (*sd_physics_fn)(sd_sim* sim, const sd_params* prm, const float* args, int32_t w,
                              float* state);

#endif /* SELFPLAYDRIVE_ABI_H */
