"""`RuleBasedDriver`: a vectorised lane follower for every agent slot of a `VecEnv`.

Per call, for all N agents at once (NumPy; the only Python loops run over route hops, waypoint
slots and successor choices, never over agents):

1. Localise each agent on a lane: nearest centerline samples (k-d tree), scored by lateral
   distance and heading agreement, lanes of the agent's planned route preferred.
2. Route: a short sequence of `route_hops` lanes from the current one. At each lane end the
   successor is the one passing closest to the next waypoint still ahead (section 2.2's
   waypoints); without waypoints left, the straightest one. A lane off the plan replans.
3. Path: `path_points` points every `path_step` m along the route ahead.
4. Speed: IDM (intelligent driver model) towards the desired speed (lane speed limit, lowered
   for curves and slower lanes ahead), interacting with the nearest object (other agent,
   obstacle, static vehicle, pedestrian) inside the path corridor, with a red or stoppable
   yellow traffic-light line on the route (section 2.2), with crossing vehicles predicted to
   reach the path first, and with a dead end.
5. Optional (`max_nudge > 0`): passing a vehicle parked partly in the lane (`_nudge.py`).
6. Steering: pure pursuit from the rear axle, inverted through the bicycle of section 2.6.
7. Output in the env's action space: nearest table entries for `DiscreteActions`, clipped
   values for `ContinuousActions`.

The driver reads only `env.state` (read-only buffer views) and the env's maps. docs/drivers.md
has the constants, the measured collision / road-edge rates and the limitations.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from selfplaydrive.drivers._lanes import MAP_SHIFT, LaneTable
from selfplaydrive.drivers._nudge import nudge_shift, shifted
from selfplaydrive.drivers._objects import corridor_leader, crossing_gap, world_objects

RED, YELLOW = 1, 2  # light states (docs/world.md): 0 off, 1 red, 2 yellow, 3 green


@dataclass(frozen=True)
class DriverParams:
    """Constants of the rule-based driver.

    Attributes:
        accel_max: IDM maximum acceleration a [m/s^2].
        decel_comfort: IDM comfortable deceleration b [m/s^2].
        decel_max: Strongest braking the driver asks for [m/s^2].
        min_gap: IDM standstill gap s0 [m] (bumper to bumper).
        time_headway: IDM time headway T [s].
        lat_accel: Lateral acceleration allowed in curves [m/s^2].
        corridor_margin: Extra lateral clearance of the path corridor [m].
        ped_margin: Extra lateral clearance around pedestrians [m].
        stop_margin: Distance kept before a red-light line [m].
        yellow_decel: A yellow light is obeyed when stopping needs at most this [m/s^2].
        lookahead_min: Shortest pure-pursuit look-ahead [m].
        lookahead_time: Look-ahead grows by speed times this [s].
        lookahead_max: Longest look-ahead [m].
        search_radius: Lane localisation radius [m].
        route_hops: Lanes kept in each agent's route.
        path_step: Spacing of the path points [m].
        path_points: Path points ahead of the agent (coverage path_step * (path_points - 1)).
        max_objects: Nearest objects ahead tested against each agent's corridor.
        predict_times: Times [s] at which crossing vehicles are extrapolated.
        crossing_cos: A vehicle whose |cos| of heading relative to the path is below this crosses.
        nudge_range: Parked vehicles up to this far ahead are passed [m].
        nudge_min_offset: A parked vehicle is passed when its centre is at least this far right
            of the path [m] (closer: it blocks the lane and the car stops behind it).
        max_nudge: Largest leftward shift of the path to pass a parked vehicle [m]; 0 (default)
            turns passing off (docs/drivers.md: with 2.0 the bundled town sees about 5 % more
            distance driven and 2.6 times the collisions).
        nudge_speed: Speed cap while passing [m/s].
        nudge_start_gap: A pass starts only this far [m] (bumper to bumper) behind the vehicle.
        nudge_clear: A pass starts only with no vehicle this far [m] ahead on the shifted line.
        nudge_extra: Clearance added to a pass beyond the corridor's [m].
        track_offset: Point that follows the path, as a share of the wheelbase behind the box
            centre (0.5: rear axle).
    """

    accel_max: float = 3.0
    decel_comfort: float = 2.5
    decel_max: float = 4.0
    min_gap: float = 2.5
    time_headway: float = 1.2
    lat_accel: float = 2.0
    corridor_margin: float = 0.4
    ped_margin: float = 1.0
    stop_margin: float = 1.0
    yellow_decel: float = 2.5
    lookahead_min: float = 3.0
    lookahead_time: float = 0.35
    lookahead_max: float = 15.0
    search_radius: float = 6.0
    route_hops: int = 8
    path_step: float = 2.0
    path_points: int = 31
    max_objects: int = 12
    track_offset: float = 0.5
    nudge_range: float = 30.0
    nudge_min_offset: float = 0.4
    max_nudge: float = 0.0
    nudge_speed: float = 4.0
    nudge_extra: float = 0.5
    nudge_start_gap: float = 10.0
    nudge_clear: float = 60.0
    predict_times: tuple[float, ...] = (0.5, 1.0, 1.5, 2.0, 3.0)
    crossing_cos: float = 0.8


class RuleBasedDriver:
    """Actions for every agent slot of `env` from its state (see the module docstring).

    Args:
        env: A `selfplaydrive.sim.VecEnv`.
        params: Driver constants (defaults: `DriverParams()`).

    Call `act()` (or the driver itself, which ignores an observation argument so it can stand
    where a policy `obs -> actions` is expected) after `env.reset` and after every `env.step`.
    """

    def __init__(self, env, params: DriverParams | None = None) -> None:
        self.env = env
        self.p = params if params is not None else DriverParams()
        self.lanes = LaneTable.build(env.maps)
        self.wheelbase_ratio = float(getattr(env.physics, "wheelbase_ratio", 0.6))
        self.table = env.action_table
        names = tuple(getattr(self.table, "names", ("accel", "steer")))
        if names != ("accel", "steer"):
            # a physics model with its own action space (physics=jerk, physics=delta): the
            # driver's controls are accelerations and steering angles, not changes or motions
            from selfplaydrive.errors import ConfigError

            raise ConfigError(
                f"rule-based driver: drives (accel, steer) actions; physics "
                f"{getattr(env.physics, 'name', type(env.physics).__name__)!r} reads {names}"
            )
        N = env.num_agents
        self.route = np.full((N, self.p.route_hops), -1, dtype=np.int64)
        self._prev_step = np.full(env.num_worlds, -1, dtype=np.int64)
        self._passing = np.zeros(N, dtype=bool)
        self.debug: dict[str, np.ndarray] = {}

    def reset(self) -> None:
        """Forget every route (they are also replanned automatically after world resets)."""
        self.route[:] = -1
        self._prev_step[:] = -1
        self._passing[:] = False

    def __call__(self, obs: np.ndarray | None = None) -> np.ndarray:
        return self.act()

    def act(self) -> np.ndarray:
        """(N, 2) actions for all slots (inactive slots get full braking, zero steering)."""
        accel, steer = self.controls()
        return self.to_actions(accel, steer)

    # ------------------------------------------------------------------------------------
    def controls(self) -> tuple[np.ndarray, np.ndarray]:
        """Continuous (acceleration [m/s^2], steering angle [rad]), each (N,) float64."""
        st, env, p = self.env.state, self.env, self.p
        A = env.agents_per_world
        w_of = np.arange(env.num_agents) // A
        self._forget_reset_worlds(st, w_of)
        alive = st.active.astype(bool)
        ego = _ego(st)
        lane, s, found = self._localise(ego, st.map_id[w_of])
        self._update_routes(lane, alive & found)
        self._extend_routes(ego, st)
        path = self._path(s, ego, found & alive)
        v = ego["v"]
        v0 = self._desired_speed(path, v, lane)
        objs = world_objects(st, A)
        drive, shift, gap_o, vl_o = self._drive_line(objs, w_of, ego, path)
        v0 = np.where(shift > 0.0, np.minimum(v0, p.nudge_speed), v0)
        gap_l = self._light_gap(path, st, w_of, v, ego)
        gap_x = crossing_gap(objs, w_of, ego, drive, p)
        gap_d = np.where(path["dead_end"], path["total"] - s - ego["hl"] - p.stop_margin, np.inf)
        a = np.minimum.reduce(
            [
                self._idm(v, v0, gap_o, v - vl_o),
                self._idm(v, v0, np.minimum(np.minimum(gap_l, gap_d), gap_x), v),
            ]
        )
        # hold a standstill: below 0.5 m/s a small deceleration would round to 0 in the
        # action table and the car would creep into the gap it keeps
        a = np.where((v < 0.5) & (a < 0.3), -p.decel_comfort, a)
        delta = self._pursuit(drive, ego, v)
        ok = alive & found
        a = np.where(ok, a, -p.decel_max)
        delta = np.where(ok, delta, 0.0)
        self.debug = dict(
            lane=lane,
            s=s,
            v0=v0,
            shift=shift,
            gap_obj=gap_o,
            gap_light=gap_l,
            gap_dead=gap_d,
            gap_cross=gap_x,
        )
        return a, delta

    def _drive_line(self, objs: dict, w_of: np.ndarray, ego: dict, path: dict) -> tuple:
        """The line driven (the lane path, shifted left while passing a parked vehicle), the
        shift [m] and the corridor leader's gap [m] and speed along the line [m/s]."""
        p, v = self.p, ego["v"]
        gap_o, vl_o = corridor_leader(objs, w_of, ego, path, p)
        if p.max_nudge <= 0.0:
            return path, np.zeros(len(v)), gap_o, vl_o
        shift = nudge_shift(objs, w_of, ego, path, p, self._passing)
        if (shift > 0.0).any():
            gap_s, vl_s = corridor_leader(objs, w_of, ego, shifted(path, shift), p)
            # a pass starts only on a clear other lane: no vehicle within nudge_clear ahead on
            # the shifted line unless it moves away at least as fast as the ego
            clear = (gap_s >= p.nudge_clear) | (vl_s >= v)
            shift = np.where(self._passing | clear, shift, 0.0)
            gap_o = np.where(shift > 0.0, gap_s, gap_o)
            vl_o = np.where(shift > 0.0, vl_s, vl_o)
        self._passing = shift > 0.0
        return shifted(path, shift), shift, gap_o, vl_o

    def to_actions(self, accel: np.ndarray, steer: np.ndarray) -> np.ndarray:
        """Map continuous controls into the env's action space."""
        t = self.table
        if t.discrete:
            ia = np.abs(accel[:, None] - t.accel[None, :].astype(np.float64)).argmin(axis=1)
            isteer = np.abs(steer[:, None] - t.steer[None, :].astype(np.float64)).argmin(axis=1)
            return np.stack([ia, isteer], axis=1).astype(np.int64)
        a = np.stack([accel, steer], axis=1)
        return np.clip(a, -t.high, t.high).astype(np.float32)

    # ------------------------------------------------------------------------------------
    def _forget_reset_worlds(self, st, w_of: np.ndarray) -> None:
        step = st.step.astype(np.int64)
        fresh = (step < self._prev_step) | (step == 0)
        self.route[fresh[w_of]] = -1
        self._passing[fresh[w_of]] = False
        self._prev_step = step.copy()

    def _localise(self, ego: dict, map_of: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Lane and arc length [m] of every agent; `found` False when no lane is near."""
        T = self.lanes
        q = np.stack([ego["x"] + map_of * MAP_SHIFT, ego["y"]], axis=1)
        k = min(16, len(T.sample_lane))
        dist, idx = T.tree.query(q, k=k, distance_upper_bound=self.p.search_radius)
        dist, idx = dist.reshape(len(q), k), idx.reshape(len(q), k)
        valid = np.isfinite(dist)
        idx = np.where(valid, idx, 0)
        cl, cs = T.sample_lane[idx], T.sample_s[idx]
        xy = np.stack([ego["x"], ego["y"]], axis=1)[:, None, :]
        pxy, tan = T.point_at(cl, cs)
        cs = np.clip(cs + ((xy - pxy) * tan).sum(-1), 0.0, T.length[cl])
        pxy, tan = T.point_at(cl, cs)
        rel = xy - pxy
        # the distance to the lane's nearest point, not only its lateral part: where the
        # projection is clipped to a lane's start (a successor a few metres ahead), the
        # along-track gap counts, else the car would jump onto the next lane before the stop
        # line at the end of its own and lose the red light on it
        lat = np.hypot(rel[..., 0], rel[..., 1])
        cosd = tan[..., 0] * ego["c"][:, None] + tan[..., 1] * ego["s"][:, None]
        cost = lat + 4.0 * (1.0 - cosd) + np.where(cosd < 0.0, 100.0, 0.0)
        on_route = (cl[:, :, None] == self.route[:, None, :3]).any(-1)
        cost = np.where(on_route, cost - 1.5, cost)
        cost = np.where(valid, cost, np.inf)
        best = cost.argmin(axis=1)
        r = np.arange(len(q))
        return cl[r, best], cs[r, best], np.isfinite(cost[r, best])

    def _update_routes(self, lane: np.ndarray, ok: np.ndarray) -> None:
        """Advance routes to the current lane; replan where it is off the plan."""
        H = self.route.shape[1]
        hit = self.route == lane[:, None]
        on = hit.any(axis=1)
        first = np.where(on, hit.argmax(axis=1), 0)
        idx = np.arange(H)[None, :] + first[:, None]
        shifted = np.take_along_axis(self.route, np.minimum(idx, H - 1), axis=1)
        self.route = np.where(idx < H, shifted, -1)
        replan = ~on
        self.route[replan] = -1
        self.route[replan, 0] = lane[replan]
        self.route[~ok] = -1

    def _extend_routes(self, ego: dict, st) -> None:
        """Fill empty hops with the successor leading towards the next waypoint ahead."""
        T, R = self.lanes, self.route
        wps = st.waypoints.astype(np.float64)
        num_wp = st.num_wp.astype(np.int64)
        K = wps.shape[1]
        j = st.wp_idx.astype(np.int64).copy()
        rows = np.arange(len(R))
        for h in range(1, R.shape[1]):
            prev = R[:, h - 1]
            live = prev >= 0
            pc = np.where(live, prev, 0)
            end = T.chord[pc, -1]
            tan = _unit(T.chord[pc, -1] - T.chord[pc, -2])
            for _ in range(K):  # skip waypoints behind the end of the lane just planned
                wp = wps[rows, np.minimum(j, K - 1)]
                behind = live & (j < num_wp) & (((wp - end) * tan).sum(-1) < 0.0)
                if not behind.any():
                    break
                j = j + behind
            need = live & (R[:, h] < 0)
            if not need.any():
                continue
            cand = T.succ[pc]  # (N, M)
            cc = np.where(cand >= 0, cand, 0)
            wp = wps[rows, np.minimum(j, K - 1)]
            to_wp = np.linalg.norm(T.chord[cc] - wp[:, None, None, :], axis=-1).min(axis=-1)
            straight = -(_unit(T.chord[cc, -1] - T.chord[cc, 0]) * tan[:, None, :]).sum(-1)
            score = np.where((j < num_wp)[:, None], to_wp, straight)
            score = np.where(cand >= 0, score, np.inf)
            best = score.argmin(axis=1)
            pick = cand[rows, best]
            R[need, h] = pick[need]

    def _path(self, s: np.ndarray, ego: dict, ok: np.ndarray) -> dict[str, np.ndarray]:
        """Points, tangents, arc lengths and lanes along each route ahead of the agent."""
        T, R, p = self.lanes, self.route, self.p
        valid = R >= 0
        rc = np.where(valid, R, 0)
        lens = np.where(valid, T.length[rc], 0.0)
        start = np.cumsum(lens, axis=1) - lens
        total = lens.sum(axis=1)
        u = s[:, None] + np.arange(p.path_points)[None, :] * p.path_step
        u = np.minimum(u, np.maximum(total, s)[:, None] - 1e-6)
        hop = ((u[:, :, None] >= start[:, None, :]) & valid[:, None, :]).sum(-1) - 1
        hop = np.maximum(hop, 0)
        lane_q = np.take_along_axis(rc, hop, axis=1)
        s_q = u - np.take_along_axis(start, hop, axis=1)
        pts, tan = T.point_at(lane_q, s_q)
        nh = valid.sum(axis=1)
        last = rc[np.arange(len(R)), np.maximum(nh - 1, 0)]
        dead = ok & (nh > 0) & (nh < R.shape[1]) & (T.succ[last, 0] < 0)
        return dict(
            pts=pts,
            tan=tan,
            arc=u - s[:, None],
            lane=lane_q,
            start=start,
            total=total,
            valid=valid,
            rc=rc,
            dead_end=dead,
            s=s,
        )

    def _desired_speed(self, path: dict, v: np.ndarray, lane: np.ndarray) -> np.ndarray:
        """Lane speed limit, lowered so the car can slow down for curves and slower lanes."""
        p, T = self.p, self.lanes
        ang = np.arctan2(path["tan"][..., 1], path["tan"][..., 0])
        dang = np.abs(np.angle(np.exp(1j * np.diff(ang, axis=1))))
        darc = np.maximum(np.diff(path["arc"], axis=1), 1e-3)
        kappa = np.where(np.diff(path["arc"], axis=1) > 0.5, dang / darc, 0.0)
        v_curve = np.sqrt(p.lat_accel / np.maximum(kappa, 1e-4))
        v_lane = T.speed_limit[path["lane"][:, 1:]]
        v_here = np.minimum(v_curve, v_lane)
        reach = np.sqrt(v_here**2 + 2.0 * p.decel_comfort * np.maximum(path["arc"][:, :-1], 0.0))
        return np.maximum(np.minimum(T.speed_limit[lane], reach.min(axis=1)), 1.0)

    def _light_gap(self, path: dict, st, w_of: np.ndarray, v: np.ndarray, ego: dict) -> np.ndarray:
        """Gap [m] to the first traffic-light line on the route that the car must stop at."""
        T, p = self.lanes, self.p
        ls = T.light_s[path["rc"]]  # (N, H, J)
        lg = T.light_group[path["rc"]]
        has = (lg >= 0) & path["valid"][..., None]
        G = self.env.dims.G
        state = st.light_state[w_of[:, None, None] * G + np.clip(lg, 0, G - 1)]
        d_line = path["start"][..., None] + ls - path["s"][:, None, None]
        gap = d_line - ego["hl"][:, None, None] - p.stop_margin
        need = v[:, None, None] ** 2 / (2.0 * np.maximum(gap, 0.1))
        ahead = d_line - ego["hl"][:, None, None] > -0.3
        stop = (
            has
            & ahead
            & (((state == RED) & (need <= p.decel_max)) | ((state == YELLOW) & (need <= p.yellow_decel)))
        )
        return np.where(stop, gap, np.inf).min(axis=(1, 2))

    def _idm(self, v: np.ndarray, v0: np.ndarray, gap: np.ndarray, dv: np.ndarray) -> np.ndarray:
        """Intelligent driver model acceleration [m/s^2] (inf gap: free road)."""
        p = self.p
        s_star = p.min_gap + np.maximum(
            0.0, v * p.time_headway + v * dv / (2.0 * np.sqrt(p.accel_max * p.decel_comfort))
        )
        inter = np.where(np.isfinite(gap), (s_star / np.maximum(gap, 0.1)) ** 2, 0.0)
        a = p.accel_max * (1.0 - (v / v0) ** 4 - inter)
        return np.where(np.isfinite(gap) & (gap <= 0.0), -p.decel_max, np.clip(a, -p.decel_max, p.accel_max))

    def _pursuit(self, path: dict, ego: dict, v: np.ndarray) -> np.ndarray:
        """Pure-pursuit steering angle [rad] through the bicycle model (section 2.6)."""
        p = self.p
        # track with the rear axle (0.5 wheelbase behind the centre): its velocity is along the
        # heading, so pure pursuit's geometry is exact there; the look-ahead is short because
        # pure pursuit cuts a curve of radius R by about ld^2 / (8 R)
        wheelbase = self.wheelbase_ratio * ego["hl"] * 2.0
        back = p.track_offset * wheelbase
        ld = np.clip(p.lookahead_min + p.lookahead_time * v, p.lookahead_min, p.lookahead_max)
        arc = path["arc"]
        want = np.maximum(ld - back, 0.5)
        q = np.minimum((arc < want[:, None]).sum(axis=1), arc.shape[1] - 1)
        r = np.arange(len(v))
        q0 = np.maximum(q - 1, 0)
        f = np.clip((want - arc[r, q0]) / np.maximum(arc[r, q] - arc[r, q0], 1e-6), 0.0, 1.0)
        tgt = path["pts"][r, q0] + f[:, None] * (path["pts"][r, q] - path["pts"][r, q0])
        rx, ry = ego["x"] - back * ego["c"], ego["y"] - back * ego["s"]
        dx, dy = tgt[:, 0] - rx, tgt[:, 1] - ry
        lx = dx * ego["c"] + dy * ego["s"]
        ly = -dx * ego["s"] + dy * ego["c"]
        d2 = np.maximum(lx**2 + ly**2, 1.0)
        return np.arctan(wheelbase * 2.0 * ly / d2)


def _ego(st) -> dict[str, np.ndarray]:
    h = st.heading.astype(np.float64)
    return dict(
        x=st.x.astype(np.float64),
        y=st.y.astype(np.float64),
        c=np.cos(h),
        s=np.sin(h),
        v=st.speed.astype(np.float64),
        hl=st.length.astype(np.float64) / 2.0,
        hw=st.width.astype(np.float64) / 2.0,
    )


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-9)
