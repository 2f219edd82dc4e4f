"""`RoadMap`: the immutable, compiled struct-of-arrays map every other part reads (section 2.1).

All geometry is float32 metres in a map-local frame; `RoadMap.origin` (float64) is the global
position of the local (0, 0), so national-grid coordinates keep their precision. Variable-length
things (polylines, successor lists) are stored CSR-style: a flat array plus `offsets` of length
count + 1, element i spanning `flat[offsets[i]:offsets[i + 1]]`.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from enum import IntEnum

import numpy as np

from selfplaydrive.maps.elements import EdgeKind, LaneKind, StopKind

__all__ = [
    "EdgeKind",
    "LaneKind",
    "Lanes",
    "Polylines",
    "RoadMap",
    "RoadSegments",
    "SegmentGrid",
    "SegmentType",
    "StopKind",
]


class SegmentType(IntEnum):
    """Type of an observed road segment (paper section 2.5)."""

    LANE_CENTER = 0
    ROAD_EDGE = 1
    STOP_LINE = 2
    TRAFFIC_LIGHT = 3
    CROSSWALK = 4


def _freeze(obj: object) -> None:
    for f in fields(obj):  # type: ignore[arg-type]
        value = getattr(obj, f.name)
        if isinstance(value, np.ndarray):
            value.flags.writeable = False


@dataclass(frozen=True)
class Polylines:
    """A set of polylines in CSR layout.

    Attributes:
        points: (P, 2) float32 [m], local frame.
        offsets: (count + 1,) int64; polyline i is points[offsets[i]:offsets[i + 1]].
    """

    points: np.ndarray
    offsets: np.ndarray

    def __post_init__(self) -> None:
        _freeze(self)

    def __len__(self) -> int:
        return len(self.offsets) - 1

    def __getitem__(self, i: int) -> np.ndarray:
        """Polyline i as a (n, 2) float32 view [m]."""
        return self.points[self.offsets[i] : self.offsets[i + 1]]

    def lengths(self) -> np.ndarray:
        """(count,) float64 length of each polyline [m]."""
        d = np.linalg.norm(np.diff(self.points.astype(np.float64), axis=0), axis=1)
        cum = np.concatenate([[0.0], np.cumsum(d)])
        # segments that straddle two polylines are excluded by differencing at the offsets
        ends = self.offsets[1:] - 1
        starts = self.offsets[:-1]
        return np.where(ends > starts, cum[np.maximum(ends, 0)] - cum[starts], 0.0)


@dataclass(frozen=True)
class Lanes:
    """Directed lanes and the lane graph.

    Attributes:
        centerlines: Centerline polylines in the direction of travel.
        width: (L,) float32 [m].
        speed_limit: (L,) float32 [m/s].
        kind: (L,) int8 `LaneKind`.
        in_junction: (L,) bool, lane lies inside an intersection or roundabout connector.
        twin: (L,) int32, reverse lane over the same geometry (bidirectional source) or -1.
        succ_offsets: (L + 1,) int32; successors of lane i are
            succ_index[succ_offsets[i]:succ_offsets[i + 1]].
        succ_index: (E,) int32.
        pred_offsets: (L + 1,) int32, predecessors, same layout.
        pred_index: (E,) int32.
        left: (L,) int32 left neighbour (same direction) or -1.
        left_legal: (L,) bool, lane change into `left` allowed.
        right: (L,) int32 right neighbour or -1.
        right_legal: (L,) bool.
        source_id: (L,) str, id of the source element.
    """

    centerlines: Polylines
    width: np.ndarray
    speed_limit: np.ndarray
    kind: np.ndarray
    in_junction: np.ndarray
    twin: np.ndarray
    succ_offsets: np.ndarray
    succ_index: np.ndarray
    pred_offsets: np.ndarray
    pred_index: np.ndarray
    left: np.ndarray
    left_legal: np.ndarray
    right: np.ndarray
    right_legal: np.ndarray
    source_id: np.ndarray

    def __post_init__(self) -> None:
        _freeze(self)

    def __len__(self) -> int:
        return len(self.width)

    def successors(self, i: int) -> np.ndarray:
        """Indices of the lanes that legally follow lane i."""
        return self.succ_index[self.succ_offsets[i] : self.succ_offsets[i + 1]]

    def predecessors(self, i: int) -> np.ndarray:
        """Indices of the lanes that legally lead into lane i."""
        return self.pred_index[self.pred_offsets[i] : self.pred_offsets[i + 1]]


@dataclass(frozen=True)
class RoadSegments:
    """Straight road segments: the road elements of the observation (section 2.5).

    Attributes:
        start: (N, 2) float32 [m] first endpoint.
        end: (N, 2) float32 [m] second endpoint.
        mid: (N, 2) float32 [m] midpoint.
        dir: (N, 2) float32 unit direction start -> end.
        length: (N,) float32 [m].
        type: (N,) int8 `SegmentType`.
        owner: (N,) int32 index of the owning element within its type's array (lane index,
            road-edge index, stop-line index, traffic-light index, crosswalk index).
    """

    start: np.ndarray
    end: np.ndarray
    mid: np.ndarray
    dir: np.ndarray
    length: np.ndarray
    type: np.ndarray
    owner: np.ndarray

    def __post_init__(self) -> None:
        _freeze(self)

    def __len__(self) -> int:
        return len(self.length)


@dataclass(frozen=True)
class SegmentGrid:
    """Uniform grid over segment midpoints for radius queries.

    Attributes:
        origin: (2,) float32 [m], lower-left corner of cell (0, 0).
        cell_size: Cell edge length [m].
        shape: (nx, ny) number of cells along x and y.
        cell_offsets: (nx * ny + 1,) int32; cell c = ix * ny + iy holds segments
            cell_items[cell_offsets[c]:cell_offsets[c + 1]].
        cell_items: (N,) int32 segment indices, each segment in the cell of its midpoint.
    """

    origin: np.ndarray
    cell_size: float
    shape: tuple[int, int]
    cell_offsets: np.ndarray
    cell_items: np.ndarray

    def __post_init__(self) -> None:
        _freeze(self)


@dataclass(frozen=True)
class RoadMap:
    """A compiled road map (section 2.1). Build one with a loader, never by hand.

    Attributes:
        name: Short name.
        source: Where it came from (path or generator call).
        origin: (2,) float64 [m], global coordinates of the local (0, 0).
        crs: Description of the global coordinate system.
        lanes: Directed lanes and lane graph.
        road_edges: Drivable-area borders.
        edge_kind: (num_edges,) int8 `EdgeKind`.
        stop_lines: Stop/yield lines (all treated as yield lines, section 2.1).
        stop_kind: (num_stop_lines,) int8 `StopKind`.
        stop_lane_offsets, stop_lane_index: CSR lanes each stop line applies to.
        light_lines: Traffic-light stop lines.
        light_group: (num_lights,) int32 signal group; lights of a group switch together.
        light_lane_offsets, light_lane_index: CSR lanes each light controls.
        crosswalks: Crosswalk outlines (open polygons: last point != first).
        segments: Derived straight segments of all of the above.
        grid: Spatial index over `segments`.
        bounds: (4,) float32 [m] xmin, ymin, xmax, ymax of all geometry (local frame).
        max_segment_length: Longest allowed segment [m] (compile parameter).
    """

    name: str
    source: str
    origin: np.ndarray
    crs: str
    lanes: Lanes
    road_edges: Polylines
    edge_kind: np.ndarray
    stop_lines: Polylines
    stop_kind: np.ndarray
    stop_lane_offsets: np.ndarray
    stop_lane_index: np.ndarray
    light_lines: Polylines
    light_group: np.ndarray
    light_lane_offsets: np.ndarray
    light_lane_index: np.ndarray
    crosswalks: Polylines
    segments: RoadSegments
    grid: SegmentGrid
    bounds: np.ndarray
    max_segment_length: float

    def __post_init__(self) -> None:
        _freeze(self)

    @property
    def num_signal_groups(self) -> int:
        """Number of distinct signal groups (max group + 1, 0 without lights)."""
        return int(self.light_group.max()) + 1 if len(self.light_group) else 0

    def vehicle_lane_km(self) -> float:
        """Centerline length of vehicle lanes [km]; twins of bidirectional lanes count once."""
        lengths = self.lanes.centerlines.lengths()
        idx = np.arange(len(self.lanes))
        once = (self.lanes.twin < 0) | (self.lanes.twin > idx)
        keep = once & (self.lanes.kind != LaneKind.BICYCLE)
        return float(lengths[keep].sum() / 1000.0)

    def query_radius(self, x: float, y: float, radius: float) -> np.ndarray:
        """Indices of segments whose midpoint lies within `radius` [m] of (x, y) (local frame).

        This is the slow, convenient Python path (tests, tools); the simulator queries the grid
        in Cython.
        """
        from selfplaydrive.maps.compile import query_grid_numpy

        return query_grid_numpy(self, x, y, radius)
