"""Suite "stop lines" (paper section 5.3): two vehicles approach a junction, one on the main
road and one on a side road behind a stop (yield) line, placed to collide at constant speed.

Generation (lane graph and geometry only):

1. For every stop line and every lane it applies to (the *side approach*), each junction lane
   Js following it is paired with every junction lane Jm of another approach whose centerline
   crosses or merges into Js's, where Jm and its predecessors carry no stop line or traffic
   light (the *main road*; a roundabout ring counts). The conflict point is the first common
   point along Js (for a merge, where the two lanes meet).
2. Each vehicle's path is its approach (straightest predecessors back, the main one never
   through a controlled lane) + its junction lane + the exit lane ahead.
3. With a time-to-conflict T ~ U(`time_to_conflict`), speeds v_main ~ U(`main_speed`) and
   v_side ~ U(`side_speed`) (capped at 0.9 x the lane speed limit), each vehicle starts
   v T metres before the conflict point along its path, so both centres reach it at time T
   at constant speed; the side vehicle must start wholly behind its stop line. Sites where the
   constant-speed boxes do not overlap (`constant_speed_collision`) are rejected, so every
   scenario really collides if nobody yields. Waypoints on each exit lane, 10 m and 30 m after
   the junction. Slot 0 is the main-road vehicle, slot 1 the side-road vehicle.

Classification (`classify_stop_line`, pure): each vehicle's centre is projected onto its path;
it *passes* the conflict point at the first frame its arc length reaches the point's. Outcome:
"collision" (either vehicle's collision term fired), else "side_yielded" (the main vehicle
passed first, or alone), "main_yielded" (the side vehicle passed first, or alone) or
"unresolved" (neither passed within the episode).

Hidden stop lines (the section 5.3 ablation): run the same scenarios with
`run_suite(..., hide_stop_lines_obs=True)`; `compare_runs` counts the scenarios whose outcome
changed.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import shapely

from selfplaydrive.eval.stats import proportion
from selfplaydrive.eval.suites.base import (
    SuiteScenario,
    Trajectory,
    blank_scenario,
    put_agent,
    warn_shortfall,
)
from selfplaydrive.eval.suites.turn_lanes import CAR_CATEGORIES
from selfplaydrive.maps.lane_paths import (
    LaneGeometry,
    boxes_overlap,
    cumlen,
    lane_linestrings,
    point_at,
    project,
    track,
)
from selfplaydrive.maps.roadmap import RoadMap
from selfplaydrive.scenario.vehicles import VehicleSizeSampler

OUTCOMES = ("collision", "side_yielded", "main_yielded", "unresolved")
MAIN, SIDE = 0, 1  # agent slots
BACK, AHEAD = 120.0, 40.0  # [m] of approach and exit kept in each vehicle's path


class StopLineSuite:
    """Generator and classifier of the stop-line suite.

    Args:
        time_to_conflict: (low, high) [s] time both vehicles need to reach the conflict point.
        main_speed: (low, high) [m/s] initial speed of the main-road vehicle.
        side_speed: (low, high) [m/s] initial speed of the side-road vehicle.
        stop_margin: Clearance [m] between the side vehicle's front and its stop line at start.
        episode_length: [s].
        tries: Draws of (T, speeds) per site before it is given up.
    """

    name = "stop_lines"

    def __init__(
        self,
        time_to_conflict: tuple[float, float] = (4.0, 7.0),
        main_speed: tuple[float, float] = (6.0, 10.0),
        side_speed: tuple[float, float] = (4.0, 7.0),
        stop_margin: float = 1.0,
        episode_length: float = 20.0,
        tries: int = 8,
    ) -> None:
        for name, r in (
            ("time_to_conflict", time_to_conflict),
            ("main_speed", main_speed),
            ("side_speed", side_speed),
        ):
            if not 0.0 < float(r[0]) <= float(r[1]):
                raise ValueError(f"{name}: expected 0 < low <= high, got {r}")
        self.time_to_conflict = (float(time_to_conflict[0]), float(time_to_conflict[1]))
        self.main_speed = (float(main_speed[0]), float(main_speed[1]))
        self.side_speed = (float(side_speed[0]), float(side_speed[1]))
        self.stop_margin = float(stop_margin)
        self.episode_length = float(episode_length)
        self.tries = int(tries)

    # -- generation -------------------------------------------------------------------------
    def sites(self, road_map: RoadMap) -> list[tuple[int, int, int, int]]:
        """All (stop line, side approach lane, side junction lane Js, main junction lane Jm)."""
        geo = LaneGeometry(road_map)
        L = geo.lanes
        controlled = _controlled(road_map)
        junction = np.flatnonzero(L.in_junction & geo.vehicle)
        lines = lane_linestrings(geo, junction)
        tree = shapely.STRtree(lines)
        out = []
        for k in range(len(road_map.stop_lines)):
            for a in road_map.stop_lane_index[
                road_map.stop_lane_offsets[k] : road_map.stop_lane_offsets[k + 1]
            ]:
                for js in L.successors(a):
                    if not (L.in_junction[js] and geo.vehicle[js]):
                        continue
                    for hit in tree.query(lines[np.searchsorted(junction, js)], predicate="intersects"):
                        jm = int(junction[hit])
                        if _is_main(geo, jm, int(js), controlled):
                            out.append((k, int(a), int(js), jm))
        return out

    def generate(
        self, road_map: RoadMap, rng: np.random.Generator, count: int, map_index: int = 0
    ) -> list[SuiteScenario]:
        """Up to `count` scenarios; sites are drawn one stop line at a time (round robin over
        shuffled stop lines) so the scenarios spread over the map; fewer with a warning."""
        geo = LaneGeometry(road_map)
        sites = self.sites(road_map)
        by_line: dict[int, list] = {}
        for s in sites:
            by_line.setdefault(s[0], []).append(s)
        queues = [list(rng.permutation(len(v))) for v in by_line.values()]
        groups = list(by_line.values())
        order = rng.permutation(len(groups))
        sizes = VehicleSizeSampler(CAR_CATEGORIES)
        out: list[SuiteScenario] = []
        while len(out) < count and any(queues):
            for g in order:
                if len(out) >= count or not queues[g]:
                    continue
                item = self._build(geo, *groups[g][queues[g].pop()], rng, sizes, map_index)
                if item is not None:
                    out.append(item)
        warn_shortfall(self.name, road_map, len(out), count, f"{len(sites)} candidate conflicts")
        return out

    def _build(self, geo, k, a, js, jm, rng, sizes, map_index) -> SuiteScenario | None:
        road_map, L = geo.road_map, geo.lanes
        controlled = _controlled(road_map)
        side = _route(geo, a, js, None)
        main = _route(geo, geo.straightest_pred(jm, lambda i: i not in controlled), jm, controlled)
        if side is None or main is None:
            return None
        (side_path, side_j0, side_chain), (main_path, main_j0, main_chain) = side, main
        conflict = _conflict_point(geo.line(js), geo.line(jm))
        if conflict is None:
            return None
        # arcs measured on the lanes themselves: a path around a roundabout may pass near itself
        sc_side = side_j0 + float(project(geo.line(js), conflict[None])[0][0])
        sc_main = main_j0 + float(project(geo.line(jm), conflict[None])[0][0])
        mid = road_map.stop_lines[k].astype(np.float64).mean(axis=0)
        stop_arc = float(side_j0 - geo.length[a] + project(geo.line(a), mid[None])[0][0])
        side_junction, main_junction = side_j0 + geo.length[js], main_j0 + geo.length[jm]
        length, width, _ = sizes.sample(rng, 2)
        for _ in range(self.tries):
            T = rng.uniform(*self.time_to_conflict)
            vm = min(rng.uniform(*self.main_speed), 0.9 * float(L.speed_limit[jm]))
            vs = min(rng.uniform(*self.side_speed), 0.9 * float(L.speed_limit[a]))
            sm, ss = sc_main - vm * T, sc_side - vs * T
            if sm < 0 or ss < 0 or ss + length[1] / 2 + self.stop_margin > stop_arc:
                continue
            item = self._item(geo, k, a, js, jm, map_index, conflict, T, (vm, vs), (sm, ss), length, width)
            item.paths.update(main=main_path, side=side_path)
            item.info.update(main_conflict_arc_m=sc_main, side_conflict_arc_m=sc_side, stop_arc_m=stop_arc)
            lanes = (geo.lane_at(main_chain, sm), geo.lane_at(side_chain, ss))
            self._place(item, main_path, side_path, main_junction, side_junction, *lanes)
            hit, _ = constant_speed_collision(item)
            if hit and _apart(item.scenario, 8.0):
                return item
        return None

    def _item(self, geo, k, a, js, jm, map_index, conflict, T, v, s, length, width) -> SuiteScenario:
        sc = blank_scenario(geo.road_map, map_index, conflict, self.episode_length)
        info = {
            "map": geo.road_map.name,
            "stop_line": int(k),
            "stop_kind": int(geo.road_map.stop_kind[k]),
            "side_lane": int(a),
            "side_junction_lane": int(js),
            "main_junction_lane": int(jm),
            "merge": bool(set(geo.lanes.successors(js)) & set(geo.lanes.successors(jm))),
            "time_to_conflict_s": float(T),
            "main_speed_mps": float(v[0]),
            "side_speed_mps": float(v[1]),
            "main_start_arc_m": float(s[0]),
            "side_start_arc_m": float(s[1]),
            "conflict_xy": [float(conflict[0]), float(conflict[1])],
            "sizes_m": [[float(length[i]), float(width[i])] for i in (0, 1)],
        }
        return SuiteScenario(self.name, sc, {}, info)

    @staticmethod
    def _place(item, main_path, side_path, main_junction, side_junction, main_lane, side_lane) -> None:
        info, sc = item.info, item.scenario
        rows = ((MAIN, main_path, main_junction, main_lane), (SIDE, side_path, side_junction, side_lane))
        for slot, path, end, lane in rows:
            key = "main" if slot == MAIN else "side"
            xy, hd = point_at(path, info[f"{key}_start_arc_m"])
            wp, _ = point_at(path, np.minimum(end + np.array([10.0, 30.0]), cumlen(path)[-1]))
            size = tuple(info["sizes_m"][slot])
            put_agent(sc, slot, xy, float(hd), info[f"{key}_speed_mps"], size, int(lane), wp)

    # -- classification ---------------------------------------------------------------------
    def classify(self, item: SuiteScenario, traj: Trajectory) -> dict[str, Any]:
        return classify_stop_line(item, traj)

    def summarise(self, outcomes: Sequence[dict[str, Any]]) -> dict[str, Any]:
        n = len(outcomes)
        res: dict[str, Any] = {"n": n}
        for name in OUTCOMES:
            res[name] = proportion(sum(o["outcome"] == name for o in outcomes), n).to_dict()
        return res


def _controlled(road_map: RoadMap) -> set[int]:
    """Lanes behind a stop line or a traffic light."""
    return {int(i) for i in road_map.stop_lane_index} | {int(i) for i in road_map.light_lane_index}


def _is_main(geo: LaneGeometry, jm: int, js: int, controlled: set[int]) -> bool:
    """Jm belongs to an uncontrolled approach other than Js's."""
    L = geo.lanes
    if jm == js or jm in controlled:
        return False
    preds = [int(p) for p in L.predecessors(jm)]
    if not preds or any(p in controlled for p in preds):
        return False
    return not (set(preds) & {int(p) for p in L.predecessors(js)})


def _route(geo: LaneGeometry, approach: int, junction: int, controlled: set[int] | None):
    """(path, arc where the junction lane starts) of the approach back `BACK` m + the junction
    lane + `AHEAD` m of exit, or None when the approach is missing."""
    if approach < 0:
        return None
    allow = None if controlled is None else (lambda i: i not in controlled)
    back = geo.chain_back(approach, BACK, allow=allow)
    nxt = geo.straightest_succ(junction)
    ahead = geo.chain_forward(nxt, AHEAD) if nxt >= 0 else []
    start = float(cumlen(geo.path(back))[-1])
    return geo.path([*back, junction, *ahead]), start, [*back, junction, *ahead]


def _conflict_point(a: np.ndarray, b: np.ndarray) -> np.ndarray | None:
    """First point along polyline `a` that `b` crosses or touches (merge: the meeting point)."""
    inter = shapely.intersection(shapely.LineString(a), shapely.LineString(b))
    pts = shapely.get_coordinates(inter)
    if len(pts) == 0:
        return None
    s, _, _ = project(a, pts)
    return pts[int(np.argmin(s))]


def _apart(sc, gap: float) -> bool:
    return float(np.hypot(*(sc.agent_xy[0] - sc.agent_xy[1]))) >= gap


def constant_speed_collision(
    item: SuiteScenario, dt: float = 0.1, horizon: float | None = None
) -> tuple[bool, float]:
    """Whether the two vehicles' boxes overlap when both keep their initial speed along their
    paths (centre on the path, heading along it); returns (hit, first time [s] or inf)."""
    info, sc = item.info, item.scenario
    horizon = sc.episode_length if horizon is None else horizon
    t = np.arange(0.0, horizon + 1e-9, dt)
    poses = []
    for key in ("main", "side"):
        s = info[f"{key}_start_arc_m"] + info[f"{key}_speed_mps"] * t
        poses.append(point_at(item.paths[key], s))
    for i in range(len(t)):
        if boxes_overlap(
            poses[0][0][i], poses[0][1][i], sc.agent_length[0], sc.agent_width[0],
            poses[1][0][i], poses[1][1][i], sc.agent_length[1], sc.agent_width[1],
        ):  # fmt: skip
            return True, float(t[i])
    return False, float("inf")


def pass_frames(item: SuiteScenario, traj: Trajectory) -> dict[str, int]:
    """First frame each vehicle's centre passes the conflict point along its path (-1: never)."""
    out = {}
    for slot, key in ((MAIN, "main"), (SIDE, "side")):
        alive = traj.active[:, slot]
        s, _, dist = track(item.paths[key], traj.xy[:, slot].astype(np.float64))
        passed = alive & (s >= item.info[f"{key}_conflict_arc_m"]) & (dist < 5.0)
        out[key] = int(np.argmax(passed)) if passed.any() else -1
    return out


def classify_stop_line(item: SuiteScenario, traj: Trajectory) -> dict[str, Any]:
    """Outcome of one stop-line episode (see the module docstring); a pure function.

    Returns:
        outcome, main_pass_s / side_pass_s (time each passed the conflict point, None when it
        did not), gap_s (time between the two passes), main_min_speed_mps / side_min_speed_mps
        (before passing).
    """
    f = pass_frames(item, traj)
    t = traj.time
    res: dict[str, Any] = {
        "main_pass_s": float(t[f["main"]]) if f["main"] >= 0 else None,
        "side_pass_s": float(t[f["side"]]) if f["side"] >= 0 else None,
    }
    for slot, key in ((MAIN, "main"), (SIDE, "side")):
        end = f[key] if f[key] >= 0 else len(t)
        v = traj.speed[:end, slot][traj.active[:end, slot]]
        res[f"{key}_min_speed_mps"] = float(v.min()) if len(v) else None
    both = res["main_pass_s"] is not None and res["side_pass_s"] is not None
    res["gap_s"] = abs(res["main_pass_s"] - res["side_pass_s"]) if both else None
    if bool(traj.collided.any()):
        res["outcome"] = "collision"
    elif f["main"] < 0 and f["side"] < 0:
        res["outcome"] = "unresolved"
    elif f["side"] < 0 or (f["main"] >= 0 and f["main"] < f["side"]):
        res["outcome"] = "side_yielded"
    else:
        res["outcome"] = "main_yielded"
    return res


def compare_runs(visible: Sequence[dict[str, Any]], hidden: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """How many scenarios changed outcome when stop lines were hidden (same order in both)."""
    if len(visible) != len(hidden):
        raise ValueError(f"compare_runs: expected equally long runs, got {len(visible)} and {len(hidden)}")
    changed = [
        i for i, (a, b) in enumerate(zip(visible, hidden, strict=True)) if a["outcome"] != b["outcome"]
    ]
    return {"n": len(visible), "changed": len(changed), "changed_indices": changed}
