# cython: language_level=3
"""Cython declarations of the component ABI (selfplaydrive_abi.h in the same folder, which
documents every field with its shape and unit; paper section 2). Compile against them with
`include_path=[selfplaydrive.get_include()]` (Cython) and `include_dirs=[...]` (C):

    from selfplaydrive_abi cimport Sim, Params, Atlas, EV_COLLIDE, C_COLLISION

Names drop the header's `sd_` / `SD_` prefixes: `Sim` is `sd_sim`, `EV_COLLIDE` is
`SD_EV_COLLIDE`. The library's own kernels cimport the same file (_sim/common.pxd).
"""

from libc.stdint cimport int8_t, uint8_t, int32_t, int64_t, uint64_t

cdef extern from "selfplaydrive_abi.h" nogil:
    int SELFPLAYDRIVE_ABI_VERSION

    cdef enum:
        SEG_LANE "SD_SEG_LANE"
        SEG_EDGE "SD_SEG_EDGE"
        SEG_STOP "SD_SEG_STOP"
        SEG_LIGHT "SD_SEG_LIGHT"
        SEG_CROSSWALK "SD_SEG_CROSSWALK"
        LIGHT_OFF "SD_LIGHT_OFF"
        LIGHT_RED "SD_LIGHT_RED"
        LIGHT_YELLOW "SD_LIGHT_YELLOW"
        LIGHT_GREEN "SD_LIGHT_GREEN"
        EV_COLLIDE "SD_EV_COLLIDE"
        EV_PED "SD_EV_PED"
        EV_OFFROAD "SD_EV_OFFROAD"
        EV_RED "SD_EV_RED"
        EV_WAYPOINT "SD_EV_WAYPOINT"
        EV_COMFORT "SD_EV_COMFORT"
        T_WAYPOINT "SD_T_WAYPOINT"
        T_COLLISION "SD_T_COLLISION"
        T_OFFROAD "SD_T_OFFROAD"
        T_RED "SD_T_RED"
        T_COMFORT "SD_T_COMFORT"
        T_CENTER "SD_T_CENTER"
        T_ALIGN "SD_T_ALIGN"
        T_VELOCITY "SD_T_VELOCITY"
        NUM_PAPER_TERMS "SD_NUM_PAPER_TERMS"
        MAX_TERMS "SD_MAX_TERMS"
        C_RADIUS "SD_C_RADIUS"
        C_COLLISION "SD_C_COLLISION"
        C_OFFROAD "SD_C_OFFROAD"
        C_RED "SD_C_RED"
        C_COMFORT "SD_C_COMFORT"
        C_CENTER "SD_C_CENTER"
        C_BIAS "SD_C_BIAS"
        C_ALIGN "SD_C_ALIGN"
        NUM_COEFFS "SD_NUM_COEFFS"
        H_FRICTION "SD_H_FRICTION"
        H_ACCEL_GAIN "SD_H_ACCEL_GAIN"
        H_STEER_GAIN "SD_H_STEER_GAIN"
        S_COLLIDE "SD_S_COLLIDE"
        S_PED "SD_S_PED"
        S_OFFROAD "SD_S_OFFROAD"
        S_RED "SD_S_RED"
        S_WAYPOINT "SD_S_WAYPOINT"
        S_COMFORT "SD_S_COMFORT"
        S_TERMINATED "SD_S_TERMINATED"
        S_TRUNCATED "SD_S_TRUNCATED"
        NUM_STATS "SD_NUM_STATS"
        PHYS_BICYCLE "SD_PHYS_BICYCLE"
        PHYS_FRICTION "SD_PHYS_FRICTION"
        PHYS_EXTERNAL "SD_PHYS_EXTERNAL"
        PHYS_COMPONENT "SD_PHYS_COMPONENT"
        EGO_DIM "SD_EGO_DIM"
        OBJ_DIM "SD_OBJ_DIM"
        ROAD_DIM "SD_ROAD_DIM"

    ctypedef struct Atlas "sd_atlas":
        int num_maps
        int num_segments
        const float* seg_mx
        const float* seg_my
        const int32_t* seg_id
        const float* seg_rec
        const float* seg_cols
        const int32_t* seg_group
        const float* grid_origin
        const float* grid_cell
        const int32_t* grid_nx
        const int32_t* grid_ny
        const int64_t* cell_base
        const int32_t* cell_offsets
        const float* max_seg_len

    ctypedef struct Params "sd_params":
        float dt
        int physics
        float wheelbase_ratio
        float gravity
        float max_speed
        int discrete
        const float* accel_table
        const float* steer_table
        float comfort_limit
        float obs_radius
        float lane_radius
        float terminate_threshold
        int obstacle_mode
        float velocity_reward
        float velocity_min
        float waypoint_reward
        float center_max_angle
        float light_min
        float light_max
        int ped_vanish
        float pos_scale
        float wp_scale
        float length_scale
        float width_scale
        float lateral_scale
        const float* coeff_scale
        int max_substeps
        float inv_pos_scale
        float inv_wp_scale
        float inv_length_scale
        float inv_width_scale
        float inv_lateral_scale
        float inv_max_speed
        double collision_speed_gain
        double center_bonus
        float center_bonus_offset
        double align_bonus

    ctypedef struct Sim "sd_sim":
        int W
        int A
        int S
        int P
        int K
        int T
        int G
        int max_obj
        int max_road
        int cand_cap
        int obs_dim
        int num_terms
        float* x
        float* y
        float* heading
        float* hcos
        float* hsin
        float* speed
        float* px
        float* py
        float* pheading
        float* length
        float* width
        float* a_long
        float* a_lat
        float* coeffs
        float* hidden
        float* waypoints
        int32_t* num_wp
        int32_t* wp_idx
        uint8_t* active
        uint8_t* obstacle
        float* lane_s
        float* lane_alpha
        uint8_t* lane_valid
        uint8_t* events
        uint8_t* ever
        int32_t* road_idx
        int32_t* road_n
        int32_t* obj_rows
        int32_t* road_rows
        float* road_r
        float* road_x
        float* road_y
        int32_t* act_i
        float* act_f
        float* reward
        float* terms
        uint8_t* term
        uint8_t* trunc
        float* obs
        float* final_obs
        float* st_x
        float* st_y
        float* st_cos
        float* st_sin
        float* st_len
        float* st_wid
        uint8_t* st_valid
        float* ped_path
        int32_t* ped_np
        float* ped_speed
        float* ped_start
        float* ped_len
        float* ped_wid
        uint8_t* ped_valid
        uint8_t* ped_here
        float* ped_x
        float* ped_y
        float* ped_px
        float* ped_py
        float* ped_cos
        float* ped_sin
        float* ped_vx
        float* ped_vy
        int8_t* light_state
        float* light_time
        int32_t* map_id
        int32_t* step
        int32_t* max_steps
        uint8_t* lights_on
        uint8_t* done
        uint64_t* rng_key
        uint64_t* rng_ctr
        double* term_sum
        int64_t* ev_count
        double* dist
        int32_t* cand
        float* cand_d
        int act_dim
        int phys_dim
        float* phys_state
        int term_state_dim
        float* term_state

    ctypedef void (*reward_term_fn "sd_reward_term_fn")(const Sim* sim, const Params* prm, const Atlas* atlas,
                                                      const float* args, int32_t w, float* out,
                                                      int32_t stride) noexcept nogil

    # ---- observation encoders (docs/components.md "Write an observation encoder") ----
    ctypedef void (*encoder_fn "sd_encoder_fn")(const Sim* sim, const Params* prm, const Atlas* atlas,
                                               const void* args, int32_t w, float* obs,
                                               int32_t stride) noexcept nogil
    # physics-model components (appended, ABI 1): one world per call (selfplaydrive_abi.h)
    ctypedef void (*physics_fn "sd_physics_fn")(Sim* sim, const Params* prm, const float* args, int32_t w,
                                                float* state) noexcept nogil
