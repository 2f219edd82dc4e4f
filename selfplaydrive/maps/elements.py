"""Loader output: plain Python lists of map elements, before compilation into a `RoadMap`.

Every loader (Lanelet2, OpenDRIVE, procedural) fills a `MapElements` and hands it to
`selfplaydrive.maps.compile.compile_map`, which validates it, recentres it, cuts the road
segments of the observation and builds the spatial grid (paper section 2.1).

Coordinates here are float64 metres in a planar frame (x east, y north). `frame_origin` is the
position of that frame's (0, 0) in the map's global coordinate system (for example the Estonian
grid L-EST97 for Tartu), so national-grid positions keep their precision.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np


class LaneKind(IntEnum):
    """What may use a lane."""

    VEHICLE = 0
    BUS = 1
    BICYCLE = 2


class StopKind(IntEnum):
    """Sign behind a stop line. The paper (section 2.1) treats both as yield lines."""

    STOP = 0
    YIELD = 1


class EdgeKind(IntEnum):
    """Where a road edge came from."""

    CURB = 0  # curbstone / kerb
    ROAD_BORDER = 1
    BARRIER = 2  # guard_rail, wall, fence
    OUTLINE = 3  # outline of the union of drivable lanes, where no edge line was mapped


@dataclass
class LaneElement:
    """One directed lane.

    Attributes:
        centerline: (n, 2) float64 [m], n >= 2, in the direction of travel.
        width: Lane width [m].
        speed_limit: [m/s].
        kind: `LaneKind`.
        source_id: Id of the source element (lanelet id, "road/section/lane" ...).
        successors: Indices (into `MapElements.lanes`) of lanes a vehicle may legally enter
            from the end of this one.
        left: Index of the lane to the left, same direction of travel, or -1.
        left_change_legal: Whether changing into `left` is allowed (dashed line).
        right: Index of the lane to the right, same direction of travel, or -1.
        right_change_legal: Whether changing into `right` is allowed.
        in_junction: True for lanes inside an intersection or roundabout connector.
        twin: For bidirectional source elements (Lanelet2 one_way=no), the index of the lane
            running the other way over the same geometry, else -1. Twins count once in lane_km.
    """

    centerline: np.ndarray
    width: float
    speed_limit: float
    kind: LaneKind = LaneKind.VEHICLE
    source_id: str = ""
    successors: list[int] = field(default_factory=list)
    left: int = -1
    left_change_legal: bool = False
    right: int = -1
    right_change_legal: bool = False
    in_junction: bool = False
    twin: int = -1


@dataclass
class PolylineElement:
    """A road edge: (n, 2) float64 [m] points, `EdgeKind`, and the source element id."""

    points: np.ndarray
    kind: EdgeKind = EdgeKind.CURB
    source_id: str = ""


@dataclass
class StopLineElement:
    """A stop or yield line: (n, 2) float64 [m] points, the lanes it applies to (indices)."""

    points: np.ndarray
    kind: StopKind = StopKind.YIELD
    lanes: list[int] = field(default_factory=list)
    source_id: str = ""


@dataclass
class TrafficLightElement:
    """A traffic-light stop line.

    Attributes:
        points: (n, 2) float64 [m] stop line.
        signal_group: Lights with the same group switch together (one regulatory element,
            one OpenDRIVE controller ...). Groups are small non-negative integers per map.
        lanes: Indices of the lanes this light controls.
        source_id: Id of the source element.
    """

    points: np.ndarray
    signal_group: int
    lanes: list[int] = field(default_factory=list)
    source_id: str = ""


@dataclass
class CrosswalkElement:
    """A crosswalk polygon: (n, 2) float64 [m] outline (not closed: last != first)."""

    polygon: np.ndarray
    source_id: str = ""


@dataclass
class MapElements:
    """Everything a loader produces; the input of `compile_map`.

    Attributes:
        name: Short map name (file stem).
        source: Path or description of the source.
        frame_origin: (2,) float64, global coordinates of this frame's (0, 0) [m].
        crs: Free-text description of the global coordinate system.
        lanes, road_edges, stop_lines, traffic_lights, crosswalks: The elements.
    """

    name: str
    source: str = ""
    frame_origin: tuple[float, float] = (0.0, 0.0)
    crs: str = "local"
    lanes: list[LaneElement] = field(default_factory=list)
    road_edges: list[PolylineElement] = field(default_factory=list)
    stop_lines: list[StopLineElement] = field(default_factory=list)
    traffic_lights: list[TrafficLightElement] = field(default_factory=list)
    crosswalks: list[CrosswalkElement] = field(default_factory=list)
