"""Geometry of the traffic rules, shared by the failure-mode suites and the reward terms.

The junction area a red light controls (paper section 5.1, "Red Lights": the paper's policy
reached the junction through the oncoming lane, around the stop line) is one definition used
twice: the red-light suite (eval/suites/red_lights.py) classifies an episode as "bypassed" when
the ego enters it without touching a red line, and the `red_intersection` reward term
(rewards/rules.py) penalises entering it while the light is red. Both build it here.

The *gate* of an approach lane is the road cross-section at its light line: the segment through
the line's point on the lane centerline, perpendicular to the lane there, `GATE_LEFT` m to the
left (the oncoming side) and `GATE_RIGHT` m to the right (the shoulder). The *controlled area*
is the rectangle `GATE_DEPTH` m deep beyond the gate: whoever is in it has passed the junction
entry of this approach, by whatever path.
"""

from __future__ import annotations

import numpy as np

from selfplaydrive.maps.elements import LaneKind
from selfplaydrive.maps.roadmap import RoadMap

GATE_LEFT = 12.0  # [m] of gate left of the line point: covers two oncoming lanes and a kerb
GATE_RIGHT = 4.0  # [m] right of it: the shoulder
GATE_DEPTH = 6.0  # [m] of controlled area beyond the gate


def gate(c: np.ndarray, heading: float) -> np.ndarray:
    """(2, 2) float64 gate end points [m]: right end first, then left end.

    Args:
        c: (2,) line point on the approach lane's centerline [m].
        heading: Approach direction there [rad].
    """
    left = np.array([-np.sin(heading), np.cos(heading)])
    c = np.asarray(c, dtype=np.float64)
    return np.stack([c - GATE_RIGHT * left, c + GATE_LEFT * left])


def controlled_area(c: np.ndarray, heading: float) -> np.ndarray:
    """(4, 2) float64 corners of the controlled area [m]: the gate's right and left ends, then
    the same `GATE_DEPTH` m further along `heading`."""
    g = gate(c, heading)
    u = np.array([np.cos(heading), np.sin(heading)])
    return np.array([g[0], g[1], g[1] + GATE_DEPTH * u, g[0] + GATE_DEPTH * u])


def line_point(road_map: RoadMap, k: int, lane: int) -> tuple[np.ndarray, float]:
    """Where light line `k` meets `lane`: the foot point on the lane centerline of the line's
    point nearest to it, and the centerline heading there.

    Returns:
        (2,) float64 point [m] and heading [rad].
    """
    path = road_map.lanes.centerlines[int(lane)].astype(np.float64)
    pts = road_map.light_lines[int(k)].astype(np.float64)
    a, d = path[:-1], np.diff(path, axis=0)
    dd = np.maximum(np.sum(d * d, axis=1), 1e-12)
    w = pts[:, None, :] - a[None]
    t = np.clip(np.sum(w * d[None], axis=2) / dd[None], 0.0, 1.0)
    gap = w - t[..., None] * d[None]
    dist2 = np.sum(gap * gap, axis=2)
    p, s = np.unravel_index(int(np.argmin(dist2)), dist2.shape)
    foot = a[s] + t[p, s] * d[s]
    return foot, float(np.arctan2(d[s, 1], d[s, 0]))


def controlled_zones(road_map: RoadMap) -> np.ndarray:
    """(n, 4) float64 zones of every (light line, controlled vehicle lane) pair: line point x,
    y [m], approach heading [rad] and signal group of the line (the lanes a line applies to are
    `light_lane_index[light_lane_offsets[k]:light_lane_offsets[k + 1]]`; bicycle lanes are
    skipped)."""
    offsets, index = road_map.light_lane_offsets, road_map.light_lane_index
    rows = []
    for k in range(len(road_map.light_lines)):
        for lane in index[offsets[k] : offsets[k + 1]]:
            if int(road_map.lanes.kind[lane]) == int(LaneKind.BICYCLE):
                continue
            c, hd = line_point(road_map, k, int(lane))
            rows.append((c[0], c[1], hd, float(road_map.light_group[k])))
    return np.array(rows, dtype=np.float64).reshape(-1, 4)
