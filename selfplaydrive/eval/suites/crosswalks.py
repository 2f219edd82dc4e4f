"""Suite "crosswalks" (paper section 5.3): the ego approaches a crosswalk with a pedestrian
waiting at the kerb ("waiting" variant) or walking across on a fixed trajectory ("crossing").

Generation (map geometry only):

1. Each crosswalk polygon's long axis (minimum rotated rectangle) is the walking line. Every
   vehicle lane whose centerline crosses the axis at more than 45 degrees gives a site; lanes
   crossing at the same point in the same direction (the left / straight / right junction
   lanes of one approach) count once, keeping the straightest.
2. The ego path is the lane's straightest predecessors back 120 m + the lane + 60 m ahead.
   X is where the path crosses the axis; the pedestrian walks the axis from one end (drawn)
   to the other, both extended `sidewalk_margin` m onto the pavement.
3. Crossing variant: pedestrian speed v_p ~ U(`ped_speed`), a lead time t0 ~ U(`ped_delay`)
   before it starts, ego speed v_e ~ U(`speed`) capped at 0.9 x the speed limit; the ego
   starts v_e (t0 + |start X| / v_p) metres before X, so at constant speed it reaches X exactly
   when the pedestrian does. The waiting variant is the same scene with the pedestrian's start
   time beyond the episode: it stands at the kerb. Waypoints 15 m and 35 m past the crosswalk.
   Sites where the ego's front would start closer than `min_gap` m to the crosswalk are skipped.

Classification (`classify_crosswalk`, pure): the ego's centre is tracked along its path and
passes when it reaches X. It *stopped* when its speed fell below `STOP_SPEED` while its front
was within `STOP_ZONE` m before the crosswalk (or at most 1 m onto it) and before passing.
Outcomes: "collision" (the ego's collision term fired), "stopped", then for a pass: waiting
variant "passed"; crossing variant "passed_in_front" (the pedestrian had not yet reached the
ego's line when the ego passed) or "passed_behind"; "road_edge" when it neither stopped there
nor passed and its road-edge term fired (it left the road: terminated, or scraping a kerb);
"other" when it neither stopped there nor passed otherwise (too slow, another route).
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
    cumlen,
    cut,
    lane_linestrings,
    point_at,
    project,
    segment_hits,
    track,
    wrap,
)
from selfplaydrive.maps.roadmap import RoadMap
from selfplaydrive.scenario.pedestrians import PATH_POINTS
from selfplaydrive.scenario.vehicles import VehicleSizeSampler

VARIANTS = ("waiting", "crossing")
OUTCOMES = {
    "waiting": ("collision", "stopped", "passed", "road_edge", "other"),
    "crossing": ("collision", "stopped", "passed_in_front", "passed_behind", "road_edge", "other"),
}
STOP_SPEED = 0.5  # [m/s] below this the ego counts as stopped
STOP_ZONE = 20.0  # [m] before the crosswalk where a stop counts as yielding
NEVER = 1.0e4  # [s] start time of a waiting pedestrian (beyond any episode)
PED_SIZE = 0.6  # [m] edge of the pedestrian's square box


class CrosswalkSuite:
    """Generator and classifier of the crosswalk suite.

    Args:
        variants: Which variants to build per site ("waiting", "crossing").
        speed: (low, high) [m/s] ego initial speed.
        ped_speed: (low, high) [m/s] walking speed.
        ped_delay: (low, high) [s] wait before the pedestrian starts walking (crossing variant).
        sidewalk_margin: Extension [m] of the walking line beyond the crosswalk at both ends.
        min_gap: Smallest start distance [m] between the ego's front and the crosswalk.
        episode_length: [s].
        tries: Draws of speeds per site before it is given up.
    """

    name = "crosswalks"

    def __init__(
        self,
        variants: Sequence[str] = VARIANTS,
        speed: tuple[float, float] = (6.0, 9.0),
        ped_speed: tuple[float, float] = (1.0, 1.6),
        ped_delay: tuple[float, float] = (0.5, 2.5),
        sidewalk_margin: float = 1.0,
        min_gap: float = 15.0,
        episode_length: float = 20.0,
        tries: int = 6,
    ) -> None:
        bad = [v for v in variants if v not in VARIANTS]
        if bad or not variants:
            raise ValueError(f"variants: expected a non-empty subset of {VARIANTS}, got {tuple(variants)}")
        for name, r in (("speed", speed), ("ped_speed", ped_speed)):
            if not 0.0 < float(r[0]) <= float(r[1]):
                raise ValueError(f"{name}: expected 0 < low <= high [m/s], got {r}")
        self.variants = tuple(variants)
        self.speed = (float(speed[0]), float(speed[1]))
        self.ped_speed = (float(ped_speed[0]), float(ped_speed[1]))
        self.ped_delay = (float(ped_delay[0]), float(ped_delay[1]))
        self.sidewalk_margin = float(sidewalk_margin)
        self.min_gap = float(min_gap)
        self.episode_length = float(episode_length)
        self.tries = int(tries)

    # -- generation -------------------------------------------------------------------------
    def sites(self, road_map: RoadMap) -> list[tuple[int, int, np.ndarray]]:
        """(crosswalk, lane, crossing point X (2,)) of every distinct lane crossing."""
        geo = LaneGeometry(road_map)
        lanes = np.flatnonzero(geo.vehicle)
        tree = shapely.STRtree(lane_linestrings(geo, lanes))
        out = []
        for c in range(len(road_map.crosswalks)):
            axis = crosswalk_axis(road_map.crosswalks[c])
            if axis is None:
                continue
            a, b, _ = axis
            best: dict[tuple, tuple[float, int, np.ndarray]] = {}
            for hit in tree.query(shapely.LineString([a, b]), predicate="intersects"):
                lane = int(lanes[hit])
                x = _crossing(geo.line(lane), a, b)
                if x is None:
                    continue
                key = (round(x[0] * 2), round(x[1] * 2), _side(a, b, geo.line(lane)))
                dev = abs(geo.turn(lane))
                if key not in best or dev < best[key][0]:
                    best[key] = (dev, lane, x)
            out.extend((c, lane, x) for _, lane, x in best.values())
        return out

    def generate(
        self, road_map: RoadMap, rng: np.random.Generator, count: int, map_index: int = 0
    ) -> list[SuiteScenario]:
        """Up to `count` sites (one per crosswalk first, round robin), each built in every
        variant: `len(variants) * sites` scenarios, variants in `self.variants` order."""
        geo = LaneGeometry(road_map)
        sites = self.sites(road_map)
        by_cw: dict[int, list] = {}
        for s in sites:
            by_cw.setdefault(s[0], []).append(s)
        groups = [by_cw[k] for k in rng.permutation(sorted(by_cw))] if by_cw else []
        queues = [list(rng.permutation(len(g))) for g in groups]
        sizes = VehicleSizeSampler(CAR_CATEGORIES)
        built: list[list[SuiteScenario]] = []
        while len(built) < count and any(queues):
            for g, q in zip(groups, queues, strict=True):
                if len(built) < count and q:
                    pair = self._build(geo, *g[q.pop()], rng, sizes, map_index, len(built))
                    if pair is not None:
                        built.append(pair)
        warn_shortfall(self.name, road_map, len(built), count, f"{len(sites)} candidate lane crossings")
        return [site[k] for k in range(len(self.variants)) for site in built]

    def _build(self, geo, cw, lane, x, rng, sizes, map_index, site) -> list[SuiteScenario] | None:
        road_map, L = geo.road_map, geo.lanes
        back = geo.chain_back(lane, 120.0)
        nxt = geo.straightest_succ(lane)
        chain = [*back, *(geo.chain_forward(nxt, 60.0) if nxt >= 0 else [])]
        path = geo.path(chain)
        lane0 = float(cumlen(geo.path(back))[-1]) - geo.length[lane]
        s_x = lane0 + float(project(geo.line(lane), x[None])[0][0])
        s_in, s_out = _extent(path, road_map.crosswalks[cw], s_x)
        a, b, _ = crosswalk_axis(road_map.crosswalks[cw])
        if rng.random() < 0.5:
            a, b = b, a
        d = (b - a) / np.hypot(*(b - a))
        start, end = a - d * self.sidewalk_margin, b + d * self.sidewalk_margin
        to_x = float(np.hypot(*(x - start)))
        length, width, _ = sizes.sample(rng, 1)
        for _ in range(self.tries):
            vp = rng.uniform(*self.ped_speed)
            t0 = rng.uniform(*self.ped_delay)
            ve = min(rng.uniform(*self.speed), 0.9 * float(L.speed_limit[lane]))
            s0 = s_x - ve * (t0 + to_x / vp)
            if s0 < 0 or s_in - s0 - length[0] / 2 < self.min_gap:
                continue
            xy, hd = point_at(path, s0)
            wp, _ = point_at(path, np.minimum(s_out + np.array([15.0, 35.0]), cumlen(path)[-1]))
            start_lane = geo.lane_at(chain, s0)
            info = {
                "map": road_map.name,
                "site": int(site),
                "crosswalk": int(cw),
                "lane": int(lane),
                "lane_id": str(L.source_id[lane]),
                "crossing_arc_m": float(s_x),
                "crosswalk_in_arc_m": float(s_in),
                "crosswalk_out_arc_m": float(s_out),
                "ego_speed_mps": float(ve),
                "ego_start_arc_m": float(s0),
                "ped_speed_mps": float(vp),
                "ped_to_crossing_m": float(to_x),
                "ped_delay_s": float(t0),
                "ego_length_m": float(length[0]),
            }
            out = []
            for variant in self.variants:
                sc = blank_scenario(road_map, map_index, x, self.episode_length)
                put_agent(sc, 0, xy, float(hd), ve, (float(length[0]), float(width[0])), start_lane, wp)
                _put_ped(sc, start, end, vp, t0 if variant == "crossing" else NEVER)
                paths = {"ego": path, "ped": np.stack([start, end])}
                out.append(SuiteScenario(self.name, sc, paths, {**info, "variant": variant}))
            return out
        return None

    # -- classification ---------------------------------------------------------------------
    def classify(self, item: SuiteScenario, traj: Trajectory) -> dict[str, Any]:
        return classify_crosswalk(item, traj)

    def summarise(self, outcomes: Sequence[dict[str, Any]]) -> dict[str, Any]:
        res: dict[str, Any] = {"n": len(outcomes)}
        for variant in VARIANTS:
            rows = [o for o in outcomes if o["variant"] == variant]
            if not rows:
                continue
            g: dict[str, Any] = {"n": len(rows)}
            for name in OUTCOMES[variant]:
                g[name] = proportion(sum(o["outcome"] == name for o in rows), len(rows)).to_dict()
            if variant == "crossing":
                k = sum(o["outcome"] in ("stopped", "passed_behind") for o in rows)
                g["yielded"] = proportion(k, len(rows)).to_dict()
            res[variant] = g
        return res


def crosswalk_axis(poly: np.ndarray) -> tuple[np.ndarray, np.ndarray, float] | None:
    """(a, b, half width) of a crosswalk outline: the long axis of its minimum rotated
    rectangle through the middle of the short sides [m]; None for a degenerate outline."""
    shape = shapely.Polygon(np.asarray(poly, dtype=np.float64))
    rect = np.asarray(shapely.minimum_rotated_rectangle(shape).exterior.coords)[:4]
    if len(rect) < 4:
        return None
    e01, e12 = np.hypot(*(rect[1] - rect[0])), np.hypot(*(rect[2] - rect[1]))
    if min(e01, e12) < 1e-6:
        return None
    if e01 >= e12:
        return (rect[3] + rect[0]) / 2, (rect[1] + rect[2]) / 2, e12 / 2
    return (rect[0] + rect[1]) / 2, (rect[2] + rect[3]) / 2, e01 / 2


def _crossing(line: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray | None:
    """Where `line` crosses segment a-b (once) at more than 45 degrees, or None."""
    pts, hd = segment_hits(line, a, b)
    if len(pts) != 1:
        return None
    axis = np.arctan2(*(b - a)[::-1])
    if abs(np.sin(float(wrap(hd[0] - axis)))) < np.sin(np.pi / 4):
        return None
    return pts[0]


def _side(a: np.ndarray, b: np.ndarray, line: np.ndarray) -> int:
    """+1 when `line` runs to the left of the a -> b direction, -1 otherwise."""
    d = line[-1] - line[0]
    return 1 if (b - a)[0] * d[1] - (b - a)[1] * d[0] > 0 else -1


def _extent(path: np.ndarray, poly: np.ndarray, s_x: float) -> tuple[float, float]:
    """Arc lengths [m] where `path` enters and leaves the crosswalk polygon near arc s_x."""
    shape = shapely.Polygon(np.asarray(poly, dtype=np.float64))
    piece_lo = max(s_x - 15.0, 0.0)
    piece = cut(path, piece_lo, s_x + 15.0)
    pts = shapely.get_coordinates(shapely.intersection(shapely.LineString(piece), shape))
    if len(pts) == 0:
        return s_x, s_x
    s, _, _ = project(piece, pts)
    return piece_lo + float(s.min()), piece_lo + float(s.max())


def _put_ped(sc, start: np.ndarray, end: np.ndarray, speed: float, start_time: float) -> None:
    """Pedestrian in slot 0 walking start -> end (three points, as the spawner's paths)."""
    pts = np.linspace(start, end, PATH_POINTS)
    sc.ped_valid[0] = True
    sc.ped_path[0] = pts
    sc.ped_num_points[0] = PATH_POINTS
    sc.ped_speed[0] = speed
    sc.ped_start_time[0] = start_time
    sc.ped_size[0] = (PED_SIZE, PED_SIZE)


def classify_crosswalk(item: SuiteScenario, traj: Trajectory, slot: int = 0) -> dict[str, Any]:
    """Outcome of one crosswalk episode (see the module docstring); a pure function.

    Returns:
        outcome, variant, pass_s (time the ego reached the walking line, None without),
        stop_s (first stop before the crosswalk, None without), ped_progress_m (pedestrian's
        distance along its line minus the ego line's, at the pass: < 0 it had not reached it).
    """
    info = item.info
    alive = traj.active[:, slot]
    s, _, dist = track(item.paths["ego"], traj.xy[:, slot].astype(np.float64))
    passed = alive & (s >= info["crossing_arc_m"]) & (dist < 5.0)
    k = int(np.argmax(passed)) if passed.any() else -1
    end = k if k >= 0 else len(s)
    front = s[:end] + info["ego_length_m"] / 2
    zone = (front >= info["crosswalk_in_arc_m"] - STOP_ZONE) & (front <= info["crosswalk_in_arc_m"] + 1.0)
    stops = np.flatnonzero(zone & alive[:end] & (traj.speed[:end, slot] < STOP_SPEED))
    ped = item.paths["ped"]
    res: dict[str, Any] = {
        "variant": info["variant"],
        "pass_s": float(traj.time[k]) if k >= 0 else None,
        "stop_s": float(traj.time[stops[0]]) if len(stops) else None,
        "ped_progress_m": None,
    }
    if k >= 0:
        u = float(np.dot(traj.ped_xy[k, 0] - ped[0], (ped[1] - ped[0]) / np.hypot(*(ped[1] - ped[0]))))
        res["ped_progress_m"] = u - info["ped_to_crossing_m"]
    if bool(traj.collided[slot]):
        res["outcome"] = "collision"
    elif len(stops):
        res["outcome"] = "stopped"
    elif k < 0:
        res["outcome"] = "road_edge" if bool(traj.offroad[slot]) else "other"
    elif info["variant"] == "waiting":
        res["outcome"] = "passed"
    else:
        res["outcome"] = "passed_in_front" if res["ped_progress_m"] < 0 else "passed_behind"
    return res
