# cython: language_level=3
"""Route waypoints of one world's agents (paper section 2.2): `RouteKernel` binds a map's route
tables once and, per reset, draws the waypoint times and route key from the world's generator,
walks the routes and places the waypoints (the lane-graph kernels of _sim/lanes.pyx).
"""

import numpy as np

cimport numpy as cnp
from numpy.random cimport bitgen_t
from selfplaydrive._sim.lanes cimport walk_one, waypoints_into
from selfplaydrive._sim.spawn_common cimport _bitgen

cnp.import_array()


cdef class RouteKernel:
    """The route tables of one map (`maps.routing.RouteTables`) and its lanes' widths and speed
    limits bound once as typed views, so a world reset pays no per-call argument conversion
    (`scenario.index.MapIndex.kernels`). hsin, hcos: sine and cosine of each centreline
    piece's heading (NumPy's, computed once)."""

    def __init__(self, tables, lane_width, speed_limit):
        """tables: `RouteTables`; lane_width, speed_limit: (L,) `Lanes.width` and
        `Lanes.speed_limit` [m, m/s] of the same map."""
        if len(lane_width) != len(tables.length) or len(speed_limit) != len(tables.length):
            raise ValueError(
                f"RouteKernel: lane_width and speed_limit need one entry per lane ({len(tables.length)}), "
                f"got {len(lane_width)} and {len(speed_limit)}"
            )
        self.tables = tables
        self.hsin = np.sin(tables.heading)
        self.hcos = np.cos(tables.heading)
        self.lane_width = np.ascontiguousarray(lane_width, dtype=np.float32)
        self.speed_limit = np.ascontiguousarray(speed_limit, dtype=np.float32)
        self.gcum = tables.gcum
        self.px = tables.px
        self.py = tables.py
        self.heading = tables.heading
        self.base = tables.base
        self.length = tables.length
        self.speed = tables.speed
        self.offsets = tables.offsets
        self.succ_off = tables.succ_offsets
        self.succ_idx = tables.succ_index
        self.left = tables.change_left
        self.right = tables.change_right
        self.has_changes = bool(tables.has_changes)
        self._lanes = None

    def waypoints(self, const i64[::1] start_lane, const f64[::1] start_s, const f64[:, ::1] times,
                  u64 key, double p_change, double min_change, Py_ssize_t max_pieces,
                  cnp.float32_t[:, :, ::1] out_xy, cnp.int32_t[::1] out_count):
        """`walk_routes` (routes lasting times[:, -1] s) then `route_waypoints_batch` in one
        call, into out_xy (A, K, 2) and out_count (A,) (the first A rows). Same results as
        `maps.routing.sample_routes` + `batch_waypoints` with the same key. The route pieces
        live in scratch kept between calls: a walk writes every entry the waypoint pass reads
        (the pieces it takes, and t_end to the last column), so nothing needs clearing."""
        self._waypoints(start_lane, start_s, times, key, p_change, min_change, max_pieces, out_xy,
                        out_count)

    def draw_waypoints(self, object rng, const i64[::1] start_lane, const f64[::1] start_s,
                       Py_ssize_t max_waypoints, double spacing, double jitter, double p_change,
                       double min_change, Py_ssize_t max_pieces, cnp.float32_t[:, :, ::1] out_xy,
                       cnp.int32_t[::1] out_count):
        """`waypoints` with its draws taken from `rng`: the times of
        `maps.routing.waypoint_times(rng, A, max_waypoints, spacing, jitter)` (cumulative sums of
        spacing * U(1 - jitter, 1 + jitter), computed as `Generator.uniform` does), then the key
        `rng.integers(0, 2**63)` (the top 63 of the next 64 random bits: what NumPy's bounded
        integer draw gives for a power-of-two range); the same values those calls give."""
        cdef Py_ssize_t a, k, n_agents = start_lane.shape[0]
        cdef bitgen_t* bg = _bitgen(rng)
        cdef double lo = 1.0 - jitter, span = (1.0 + jitter) - (1.0 - jitter), acc
        cdef u64 key
        times_arr = np.empty((n_agents, max_waypoints))
        cdef f64[:, ::1] times = times_arr
        with rng.bit_generator.lock:
            for a in range(n_agents):
                acc = 0.0
                for k in range(max_waypoints):
                    acc = acc + spacing * (lo + span * bg.next_double(bg.state))
                    times[a, k] = acc
            key = bg.next_uint64(bg.state) >> 1
        self._waypoints(start_lane, start_s, times, key, p_change, min_change, max_pieces, out_xy,
                        out_count)

    cdef int _waypoints(self, const i64[::1] start_lane, const f64[::1] start_s, const f64[:, ::1] times,
                        u64 key, double p_change, double min_change, Py_ssize_t max_pieces,
                        cnp.float32_t[:, :, ::1] out_xy, cnp.int32_t[::1] out_count) except -1:
        """The body of `waypoints`."""
        cdef Py_ssize_t a, n_agents = start_lane.shape[0], K = times.shape[1]
        cdef double s
        cdef bint changes = p_change > 0 and self.has_changes
        cdef cnp.npy_bool dead = False
        if n_agents == 0:
            return 0
        if self._lanes is None or self._lanes.shape[0] < n_agents or self._lanes.shape[1] != max_pieces:
            self._lanes = np.empty((n_agents, max_pieces), dtype=np.int64)
            self._s0 = np.empty((n_agents, max_pieces))
            self._s1 = np.empty((n_agents, max_pieces))
            self._t_end = np.empty((n_agents, max_pieces))
            self._change = np.empty((n_agents, max_pieces), dtype=bool)
        cdef i64[:, ::1] lanes = self._lanes
        cdef f64[:, ::1] s0 = self._s0, s1 = self._s1, t_end = self._t_end
        cdef cnp.npy_bool[:, ::1] change = self._change
        # the GIL stays held: Python threads sharing this map's kernel cannot interleave on
        # the scratch
        for a in range(n_agents):
            s = start_s[a]
            if s < 0.0:
                s = 0.0
            if s > self.length[start_lane[a]]:
                s = self.length[start_lane[a]]
            walk_one(self.succ_off, self.succ_idx, self.left, self.right, self.length,
                      self.speed, start_lane[a], s, times[a, K - 1], key, a, p_change,
                      min_change, changes, lanes[a], s0[a], s1[a], change[a], t_end[a], &dead)
        waypoints_into(lanes[:n_agents], s0[:n_agents], s1[:n_agents], t_end[:n_agents],
                         times, self.speed, self.gcum, self.px, self.py, self.base,
                         self.length, self.offsets, out_xy, out_count)
        return 0
