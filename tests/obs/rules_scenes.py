"""Hand-built map and scenes of the traffic-rule encoder tests (tests/obs/test_rules_obs.py):
a straight two-lane road with a STOP line, a YIELD line and two crosswalks."""

from __future__ import annotations

import copy

import numpy as np
from loadfile import load_sim_helpers

from selfplaydrive.maps import (
    CrosswalkElement,
    LaneElement,
    MapElements,
    PolylineElement,
    StopKind,
    StopLineElement,
    compile_map,
)

make_scenario = load_sim_helpers().make_scenario

W = 3.5  # [m] lane width
STOP_MID = (20.0, -W / 2)  # STOP line across the east lane at x = 20
YIELD_MID = (-20.0, W / 2)  # YIELD line across the west lane at x = -20
CW_EAST = np.array([[40.0, -W], [43.0, -W], [43.0, W], [40.0, W]])  # crosswalk x 40..43
CW_WEST = np.array([[-43.0, -W], [-40.0, -W], [-40.0, W], [-43.0, W]])  # x -43..-40


def rules_map():
    """The road along x (lanes at y = -1.75 eastbound and +1.75 westbound, 200 m), edges at
    y = +-3.5, a STOP line at x = 20, a YIELD line at x = -20, crosswalks at x 40..43 and -43..-40."""
    lanes = [
        LaneElement(np.array([[-100.0, -W / 2], [100.0, -W / 2]]), width=W, speed_limit=13.9, source_id="e"),
        LaneElement(np.array([[100.0, W / 2], [-100.0, W / 2]]), width=W, speed_limit=13.9, source_id="w"),
    ]
    edges = [
        PolylineElement(np.array([[-100.0, -W], [100.0, -W]]), source_id="south"),
        PolylineElement(np.array([[-100.0, W], [100.0, W]]), source_id="north"),
    ]
    stops = [
        StopLineElement(np.array([[20.0, -W], [20.0, 0.0]]), kind=StopKind.STOP, lanes=[0]),
        StopLineElement(np.array([[-20.0, 0.0], [-20.0, W]]), kind=StopKind.YIELD, lanes=[1]),
    ]
    walks = [CrosswalkElement(CW_EAST, source_id="cw_e"), CrosswalkElement(CW_WEST, source_id="cw_w")]
    return compile_map(
        MapElements(name="rules", lanes=lanes, road_edges=edges, stop_lines=stops, crosswalks=walks)
    )


class SceneSpawner:
    """One agent at the origin heading east (it sees the whole map) and the given pedestrians
    (dicts of make_scenario: path, speed, start)."""

    def __init__(self, peds=()) -> None:
        self.scene = make_scenario(
            [dict(xy=(0.0, -W / 2), heading=0.0, speed=0.0, waypoints=[(30.0, -W / 2)])],
            A=1,
            S=1,
            P=max(len(peds), 1),
            peds=peds,
        )

    def sample(self, road_map, rng, map_index: int = 0):
        rng.random()
        return copy.deepcopy(self.scene)
