"""Suite "stop signs" (paper section 5.1, "Stop Signs"): does the vehicle behind a STOP line
come to a full stop, and does it only when cross traffic approaches?

The paper's policy has no reward for stopping at stop lines (section 2.1 treats every stop line
as a yield line) and was seen to "stop at stop signs, but only when another vehicle is
approaching the intersection". This suite measures that split.

Generation: the conflicts of the stop-line suite (`StopLineSuite`: a side vehicle behind the
line and a main-road vehicle timed to reach the conflict point together), restricted to the
line kinds asked for (`StopKind` of the map: STOP, and YIELD reported apart since the paper
does not penalise passing a yield line). The side vehicle starts with its front at least
`min_gap` m before the line, so a full stop is always possible. Each conflict gives two
scenarios: "with" cross traffic (both vehicles) and "without" (the main-road vehicle removed),
identical otherwise. Slot 1, the side vehicle, is the one classified.

Classification (`classify_stop_sign`, pure): the side vehicle's front (centre arc + half its
length along its path) *passes* the line when it is `PASS_MARGIN` m beyond it. Its lowest
speed while the front is in the zone from `STOP_ZONE` m before the line to `PASS_MARGIN` m past
it (before passing) decides: "full_stop" below `FULL_STOP` m/s, "rolling_stop" below
`ROLLING_STOP` m/s, else "no_stop". A vehicle that stopped in the zone and never passed is a
full stop (still waiting). Without a pass and without a stop in the zone: "collision" when its
collision term fired, else "not_reached" (stopped short of the zone or too slow to get there).
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from typing import Any

import numpy as np

from selfplaydrive.eval.stats import proportion
from selfplaydrive.eval.suites.base import SuiteScenario, Trajectory
from selfplaydrive.eval.suites.stop_lines import MAIN, SIDE, StopLineSuite
from selfplaydrive.maps.lane_paths import track
from selfplaydrive.maps.roadmap import RoadMap, StopKind

OUTCOMES = ("full_stop", "rolling_stop", "no_stop", "not_reached", "collision")
KINDS = ("stop", "yield")
TRAFFIC = ("with", "without")
FULL_STOP = 0.5  # [m/s] below this the vehicle has stopped
ROLLING_STOP = 3.0  # [m/s] below this (and not stopped) it slowed down: a rolling stop
STOP_ZONE = 8.0  # [m] before the line where the front must be when it stops
PASS_MARGIN = 0.5  # [m] past the line at which the front has passed it


class StopSignSuite(StopLineSuite):
    """Generator and classifier of the stop-sign suite.

    Args:
        kinds: Line kinds to build ("stop", "yield").
        min_gap: Smallest distance [m] between the side vehicle's front and its line at start.
        time_to_conflict, main_speed, side_speed, episode_length, tries: As `StopLineSuite`
            (longer times by default, so the side vehicle can start `min_gap` m back).
    """

    name = "stop_signs"

    def __init__(
        self,
        kinds: Sequence[str] = KINDS,
        min_gap: float = 15.0,
        time_to_conflict: tuple[float, float] = (5.0, 8.0),
        main_speed: tuple[float, float] = (6.0, 10.0),
        side_speed: tuple[float, float] = (5.0, 8.0),
        episode_length: float = 20.0,
        tries: int = 16,
    ) -> None:
        bad = [k for k in kinds if k not in KINDS]
        if bad or not kinds:
            raise ValueError(f"kinds: expected a non-empty subset of {KINDS}, got {tuple(kinds)}")
        super().__init__(time_to_conflict, main_speed, side_speed, min_gap, episode_length, tries)
        self.kinds = tuple(kinds)

    def sites(self, road_map: RoadMap) -> list[tuple[int, int, int, int]]:
        """The stop-line suite's conflicts behind lines of the kinds asked for."""
        want = {StopKind.STOP if k == "stop" else StopKind.YIELD for k in self.kinds}
        return [s for s in super().sites(road_map) if StopKind(int(road_map.stop_kind[s[0]])) in want]

    def generate(
        self, road_map: RoadMap, rng: np.random.Generator, count: int, map_index: int = 0
    ) -> list[SuiteScenario]:
        """Up to `count` conflicts, each as a "with" and a "without" cross-traffic scenario:
        the `count` "with" scenarios first, then the same conflicts "without"."""
        with_traffic = super().generate(road_map, rng, count, map_index)
        for item in with_traffic:
            item.info.update(kind=_kind(item.info["stop_kind"]), traffic="with")
        return with_traffic + [_without(item) for item in with_traffic]

    def classify(self, item: SuiteScenario, traj: Trajectory) -> dict[str, Any]:
        return classify_stop_sign(item, traj)

    def summarise(self, outcomes: Sequence[dict[str, Any]]) -> dict[str, Any]:
        return summarise_stop_signs(outcomes)


def _kind(stop_kind: int) -> str:
    return "stop" if StopKind(int(stop_kind)) == StopKind.STOP else "yield"


def _without(item: SuiteScenario) -> SuiteScenario:
    """The same scene with the main-road vehicle removed (its slot invalid)."""
    sc = copy.deepcopy(item.scenario)
    sc.agent_valid[MAIN] = False
    return SuiteScenario(item.suite, sc, dict(item.paths), {**item.info, "traffic": "without"})


def classify_stop_sign(item: SuiteScenario, traj: Trajectory) -> dict[str, Any]:
    """Outcome of one stop-sign episode (see the module docstring); a pure function.

    Returns:
        outcome, kind, traffic, min_zone_speed_mps (lowest speed in the zone before passing,
        None when the front never got there), pass_s (time the front passed, None without),
        stop_s (first full stop in the zone, None without), collided.
    """
    info = item.info
    alive = traj.active[:, SIDE]
    s, _, dist = track(item.paths["side"], traj.xy[:, SIDE].astype(np.float64))
    front = s + float(item.scenario.agent_length[SIDE]) / 2 - info["stop_arc_m"]
    passed = alive & (front >= PASS_MARGIN) & (dist < 5.0)
    k = int(np.argmax(passed)) if passed.any() else -1
    end = k if k >= 0 else len(front)
    zone = alive[:end] & (front[:end] >= -STOP_ZONE)
    v = traj.speed[:end, SIDE][zone]
    stops = np.flatnonzero(zone & (traj.speed[:end, SIDE] < FULL_STOP))
    res: dict[str, Any] = {
        "kind": info["kind"],
        "traffic": info["traffic"],
        "pair": _pair_key(info),
        "min_zone_speed_mps": float(v.min()) if len(v) else None,
        "pass_s": float(traj.time[k]) if k >= 0 else None,
        "stop_s": float(traj.time[stops[0]]) if len(stops) else None,
        "collided": bool(traj.collided[SIDE]),
    }
    if len(stops):
        res["outcome"] = "full_stop"
    elif k >= 0:
        res["outcome"] = "rolling_stop" if res["min_zone_speed_mps"] < ROLLING_STOP else "no_stop"
    elif res["collided"]:
        res["outcome"] = "collision"
    else:
        res["outcome"] = "not_reached"
    return res


def summarise_stop_signs(outcomes: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Outcome shares per line kind and cross traffic, and per kind the conflicts where the
    vehicle stopped fully only with cross traffic (the paper's observation)."""
    res: dict[str, Any] = {"n": len(outcomes)}
    for kind in KINDS:
        rows = [o for o in outcomes if o["kind"] == kind]
        if not rows:
            continue
        g: dict[str, Any] = {"n": len(rows)}
        for traffic in TRAFFIC:
            sub = [o for o in rows if o["traffic"] == traffic]
            t: dict[str, Any] = {"n": len(sub)}
            for name in OUTCOMES:
                t[name] = proportion(sum(o["outcome"] == name for o in sub), len(sub)).to_dict()
            g[traffic] = t
        g["paired"] = _paired(rows)
        res[kind] = g
    return res


def _pair_key(info: dict[str, Any]) -> str:
    """Identifies a conflict across its "with" and "without" scenarios."""
    keys = ("map", "stop_line", "side_lane", "side_junction_lane", "main_junction_lane")
    return ":".join(str(info[k]) for k in keys) + f":{info['side_start_arc_m']:.3f}"


def _paired(rows: Sequence[dict[str, Any]]) -> dict[str, int]:
    """Counts over conflicts run both ways: full stop in both, only with cross traffic, only
    without, neither."""
    by: dict[str, dict[str, bool]] = {}
    for o in rows:
        by.setdefault(o["pair"], {})[o["traffic"]] = o["outcome"] == "full_stop"
    out = {"both": 0, "only_with_traffic": 0, "only_without_traffic": 0, "neither": 0}
    for got in by.values():
        if len(got) != 2:
            continue
        fa, fb = got["with"], got["without"]
        if fa and fb:
            out["both"] += 1
        else:
            out["only_with_traffic" if fa else "only_without_traffic" if fb else "neither"] += 1
    return out
