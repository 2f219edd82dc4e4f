"""Road maps: the `RoadMap` model, loaders and routing (paper section 2.1)."""

from selfplaydrive.maps.compile import compile_map
from selfplaydrive.maps.elements import (
    CrosswalkElement,
    EdgeKind,
    LaneElement,
    LaneKind,
    MapElements,
    PolylineElement,
    StopKind,
    StopLineElement,
    TrafficLightElement,
)
from selfplaydrive.maps.roadmap import RoadMap, SegmentType

__all__ = [
    "CrosswalkElement",
    "EdgeKind",
    "LaneElement",
    "LaneKind",
    "MapElements",
    "PolylineElement",
    "RoadMap",
    "SegmentType",
    "StopKind",
    "StopLineElement",
    "TrafficLightElement",
    "compile_map",
]
