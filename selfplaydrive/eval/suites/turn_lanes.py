"""Suite "turning from the correct lane" (paper section 5.3): the ego must turn at the next
junction but starts in a lane from which the turn is not legal, so it has to change lanes.

Generation (from the lane graph only, so it works on procedural and Lanelet2 maps): the sites,
turns J with a wrong start lane W beside their correct lanes, come from
`scenario.turn_sites.TurnSites` (its docstring has the rules; the turn-lane training starts use
the same search).

At a site drawn at random, the ego is placed on W's centerline, heading along it,
`start_distance` m (drawn) before J's start measured along the correct corridor, at least 0.75
lane widths beside it, leaving at least `change_room` m of W ahead when the change must happen
on W itself. Initial speed U(`speed`) capped by 0.8 times the speed limit; a car-sized vehicle;
waypoints on the exit lane 10 m and 30 m after the junction force the turn.

Classification (`classify_turn`, pure, from the trajectory): the ego *turned* when its centre
came within half a lane width + 1 m of the exit lane, heading within 45 degrees of it. The
*entry* is the first frame its centre crosses the line through J's start perpendicular to the
approach; the entry offset is its lateral distance from the correct lane's centre there. The
outcome is "correct_lane" (turned, entry offset below half the lane width), "wrong_lane"
(turned from elsewhere) or "no_turn". The lane change time is the start of the last unbroken
run of frames with the centre inside the correct lane before the entry; the report gives how
many seconds (and metres) before the entry the ego changed lanes.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from selfplaydrive.eval.stats import mean_estimate, proportion
from selfplaydrive.eval.suites.base import (
    SuiteScenario,
    Trajectory,
    blank_scenario,
    put_agent,
    warn_shortfall,
)
from selfplaydrive.maps.lane_paths import LaneGeometry, point_at, project, wrap
from selfplaydrive.maps.roadmap import RoadMap
from selfplaydrive.scenario.turn_sites import SiteStarts, TurnSites
from selfplaydrive.scenario.vehicles import DEFAULT_CATEGORIES, VehicleSizeSampler

OUTCOMES = ("correct_lane", "wrong_lane", "no_turn")
CAR_CATEGORIES = tuple(c for c in DEFAULT_CATEGORIES if c[0] in ("small_car", "car", "suv_van"))


class TurnLaneSuite:
    """Generator and classifier of the turning-from-the-correct-lane suite.

    Args:
        min_turn: Heading change [rad] that makes a junction lane a turn.
        start_distance: (low, high) distance [m] of the start before the junction.
        speed: (low, high) initial speed [m/s], capped by 0.8 x the lane speed limit.
        change_room: Lane length [m] left ahead of the start when the change is due on it.
        search_back: How far back [m] correct lanes are searched.
        episode_length: [s].
        entry_waypoint: None (the paper's suite): the ego's only waypoints lie after the
            junction. A distance [m]: a first waypoint on the correct lane this far before the
            junction's start as well, which tells the ego which lane to take (a diagnostic
            variant: does a policy fail for want of that information, or of the lane change?).
    """

    name = "turn_lanes"

    def __init__(
        self,
        min_turn: float = 0.7,
        start_distance: tuple[float, float] = (30.0, 100.0),
        speed: tuple[float, float] = (5.0, 8.0),
        change_room: float = 12.0,
        search_back: float = 250.0,
        episode_length: float = 25.0,
        entry_waypoint: float | None = None,
    ) -> None:
        self.finder = TurnSites(min_turn, start_distance, change_room, search_back)
        if not 0.0 <= speed[0] <= speed[1]:
            raise ValueError(f"speed: expected 0 <= low <= high [m/s], got {speed}")
        self.speed = (float(speed[0]), float(speed[1]))
        self.episode_length = float(episode_length)
        if entry_waypoint is not None and not entry_waypoint >= 0.0:
            raise ValueError(f"entry_waypoint: expected None or a distance >= 0 [m], got {entry_waypoint!r}")
        self.entry_waypoint = None if entry_waypoint is None else float(entry_waypoint)

    # -- generation -------------------------------------------------------------------------
    def sites(self, road_map: RoadMap) -> list[tuple[int, int, int]]:
        """All (junction lane J, its approach lane P, wrong start lane W) triples of the map."""
        return self.finder.sites(LaneGeometry(road_map))

    def generate(
        self, road_map: RoadMap, rng: np.random.Generator, count: int, map_index: int = 0
    ) -> list[SuiteScenario]:
        """Up to `count` scenarios at distinct sites (random order); fewer with a warning."""
        geo = LaneGeometry(road_map)
        sites = self.finder.sites(geo)
        order = rng.permutation(len(sites))
        sizes = VehicleSizeSampler(CAR_CATEGORIES)
        out: list[SuiteScenario] = []
        for i in order:
            if len(out) >= count:
                break
            item = self._build(geo, *sites[i], rng, sizes, map_index)
            if item is not None:
                out.append(item)
        warn_shortfall(self.name, road_map, len(out), count, f"{len(sites)} candidate sites")
        return out

    def site_starts(self, geo: LaneGeometry, j: int, p: int, w: int) -> SiteStarts | None:
        """Every admissible start of site (j, p, w) (`TurnSites.site_starts`)."""
        return self.finder.site_starts(geo, j, p, w)

    def _build(self, geo, j, p, w, rng, sizes, map_index) -> SuiteScenario | None:
        """One scenario at site (j, p, w), or None when no start point fits."""
        L = geo.lanes
        nonj = lambda i: not L.in_junction[i]  # noqa: E731
        st = self.site_starts(geo, j, p, w)
        if st is None:
            return None
        k = int(rng.choice(len(st.xy)))
        xy, hd, d_entry = st.xy, st.heading, st.d_entry
        corridor, s_entry, exit_path = st.corridor, st.s_entry, st.exit_path
        length, width, _ = sizes.sample(rng, 1)
        v = min(rng.uniform(*self.speed), 0.8 * float(L.speed_limit[w]))
        wp = st.exit_waypoints
        if self.entry_waypoint is not None:
            if d_entry[k] <= self.entry_waypoint:
                return None  # the start would already be past the entry waypoint
            lead, _ = point_at(corridor, np.array([s_entry - self.entry_waypoint]))
            wp = np.concatenate([lead, wp])
        sc = blank_scenario(geo.road_map, map_index, xy[k], self.episode_length)
        put_agent(sc, 0, xy[k], float(hd[k]), v, (float(length[0]), float(width[0])), w, wp)
        wrong = geo.path(geo.chain_forward(w, 250.0, allow=nonj))
        info = {
            "map": geo.road_map.name,
            "turn": "left" if geo.turn(j) > 0 else "right",
            "junction_lane": int(j),
            "approach_lane": int(p),
            "start_lane": int(w),
            "start_lane_id": str(L.source_id[w]),
            "junction_lane_id": str(L.source_id[j]),
            "start_distance_m": float(d_entry[k]),
            "start_speed_mps": float(v),
            "lane_width_m": float(L.width[p]),
            "entry_arc_m": float(s_entry),
        }
        paths = {"corridor": corridor, "exit": exit_path, "wrong": wrong}
        return SuiteScenario(self.name, sc, paths, info)

    # -- classification ---------------------------------------------------------------------
    def classify(self, item: SuiteScenario, traj: Trajectory) -> dict[str, Any]:
        return classify_turn(item, traj)

    def summarise(self, outcomes: Sequence[dict[str, Any]]) -> dict[str, Any]:
        return summarise_turns(outcomes)


# -- classifier ---------------------------------------------------------------------------------
def classify_turn(item: SuiteScenario, traj: Trajectory, slot: int = 0) -> dict[str, Any]:
    """Outcome of one turn-lane episode (see the module docstring); a pure function.

    Returns:
        outcome ("correct_lane" | "wrong_lane" | "no_turn"), turn ("left" | "right"),
        entry_offset_m, lane_change_lead_s / lane_change_lead_m (None without a change into
        the correct lane before the entry), collided.
    """
    corridor, exit_path = item.paths["corridor"], item.paths["exit"]
    width = float(item.info["lane_width_m"])
    s_entry = float(item.info["entry_arc_m"])
    alive = traj.active[:, slot]
    xy = traj.xy[:, slot].astype(np.float64)[alive]
    hd = traj.heading[:, slot].astype(np.float64)[alive]
    t = traj.time[alive]
    out: dict[str, Any] = {
        "outcome": "no_turn",
        "turn": item.info["turn"],
        "entry_offset_m": None,
        "lane_change_lead_s": None,
        "lane_change_lead_m": None,
        "collided": bool(traj.collided[slot]),
    }
    if len(xy) < 2:
        return out
    s_c, lat_c, _ = project(corridor, xy)
    entry = np.flatnonzero((s_c[1:] >= s_entry) & (s_c[:-1] < s_entry) & (np.abs(lat_c[1:]) < 3 * width))
    turned = _turned(exit_path, xy, hd, width)
    if len(entry):
        e = int(entry[0]) + 1
        out["entry_offset_m"] = float(abs(lat_c[e]))
        inside = (np.abs(lat_c[:e]) < width / 2) & (s_c[:e] > 0.5)
        if inside[-1] and not inside.all():
            c = int(np.flatnonzero(~inside)[-1]) + 1  # first frame of the last run inside
            out["lane_change_lead_s"] = float(t[e] - t[c])
            out["lane_change_lead_m"] = float(s_entry - s_c[c])
    if turned:
        correct = out["entry_offset_m"] is not None and out["entry_offset_m"] < width / 2
        out["outcome"] = "correct_lane" if correct else "wrong_lane"
    return out


def _turned(exit_path: np.ndarray, xy: np.ndarray, hd: np.ndarray, width: float) -> bool:
    """The centre came onto the exit lane (5 to 40 m along it), heading within 45 deg."""
    s, _, dist = project(exit_path, xy)
    _, lane_hd = point_at(exit_path, s)
    on = (dist < width / 2 + 1.0) & (s > 5.0) & (s < 40.0) & (np.abs(wrap(hd - lane_hd)) < np.pi / 4)
    return bool(on.any())


def summarise_turns(outcomes: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Proportions per outcome (all, left, right) and lane-change lead times [s] by direction."""
    res: dict[str, Any] = {"n": len(outcomes)}
    for group in ("all", "left", "right"):
        rows = [o for o in outcomes if group == "all" or o["turn"] == group]
        g: dict[str, Any] = {"n": len(rows)}
        for name in OUTCOMES:
            g[name] = proportion(sum(o["outcome"] == name for o in rows), len(rows)).to_dict()
        lead = np.array([o["lane_change_lead_s"] for o in rows if o["lane_change_lead_s"] is not None])
        g["lane_change_lead_s"] = mean_estimate(lead).to_dict() if len(lead) >= 2 else None
        g["lane_change_lead_s_median"] = float(np.median(lead)) if len(lead) else None
        res[group] = g
    return res
