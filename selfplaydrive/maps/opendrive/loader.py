"""`read_opendrive` and the Hydra-constructible `OpenDriveLoader` (paper section 2.1)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from selfplaydrive.errors import ConfigError, MapError
from selfplaydrive.maps.compile import compile_map
from selfplaydrive.maps.elements import LaneElement, MapElements
from selfplaydrive.maps.opendrive.edges import junction_edges, road_edges
from selfplaydrive.maps.opendrive.geometry import ReferenceLine
from selfplaydrive.maps.opendrive.graph import link_lanes
from selfplaydrive.maps.opendrive.lanes import (
    LaneIndex,
    assign_neighbours,
    build_lanes,
    contract,
    snap_dangling,
)
from selfplaydrive.maps.opendrive.parse import parse_opendrive
from selfplaydrive.maps.opendrive.sections import sample_road
from selfplaydrive.maps.opendrive.signals import crosswalks, signal_elements
from selfplaydrive.maps.roadmap import RoadMap

DEFAULT_SPEED_LIMIT = 50.0 / 3.6  # [m/s] where the file gives none
MAX_EXTENT = 1.0e5  # [m] OpenDRIVE maps are local; a wider lane bounding box means a corrupt number


def read_opendrive(
    path: str | Path,
    sample_step: float = 1.0,
    default_speed_limit: float = DEFAULT_SPEED_LIMIT,
    snap_tolerance: float = 0.3,
) -> MapElements:
    """Read an OpenDRIVE file into `MapElements`.

    Args:
        path: The .xodr file.
        sample_step: Longest distance between centerline / edge samples along a road [m].
        default_speed_limit: Speed limit of lanes without a <speed> record [m/s].
        snap_tolerance: Lane ends without any successor are linked to lane starts without any
            predecessor within this distance [m] (0 disables; covers files with missing links).

    Returns:
        Lanes (with successors, neighbours, in-junction flags), road edges, stop/yield lines,
        traffic lights and crosswalks, in the file's x/y frame [m].

    Raises:
        MapError: Naming the file and element (road, lane, signal ...) on malformed input or a
            map without drivable lanes.
    """
    path = str(path)
    if not (sample_step > 0 and default_speed_limit > 0):
        raise MapError(
            f"sample_step={sample_step} and default_speed_limit={default_speed_limit} must be positive", path
        )
    # corrupt numbers may overflow on the way; every result is checked for finiteness below
    with np.errstate(all="ignore"):
        return _read(path, sample_step, default_speed_limit, snap_tolerance)


def _read(path: str, sample_step: float, default_speed_limit: float, snap_tolerance: float) -> MapElements:
    odr = parse_opendrive(path)
    refs = {rid: ReferenceLine(r.geometries, path, f"road {rid}") for rid, r in odr.roads.items()}
    geoms = [g for rid, road in odr.roads.items() for g in sample_road(road, refs[rid], sample_step)]
    index = LaneIndex()
    lanes = build_lanes(geoms, default_speed_limit, index)
    if not lanes:
        raise MapError("map has no drivable lanes (driving, bus, biking ...) of positive width", path)
    _check_extent(lanes, path)
    link_lanes(lanes, index, odr, refs)
    lanes = contract(lanes, index)
    assign_neighbours(lanes, index)
    if snap_tolerance > 0:
        snap_dangling(lanes, snap_tolerance)
    stops, lights = signal_elements(odr, refs, index, lanes)
    return MapElements(
        name=Path(path).stem,
        source=path,
        crs="OpenDRIVE local x/y",
        lanes=lanes,
        road_edges=road_edges(geoms) + junction_edges(odr, index),
        stop_lines=stops,
        traffic_lights=lights,
        crosswalks=crosswalks(odr, refs),
    )


def _check_extent(lanes: list[LaneElement], path: str) -> None:
    """Raise MapError naming the lane farthest from the median if the map is implausibly wide."""
    pts = np.concatenate([lane.centerline for lane in lanes])
    if np.all(np.ptp(pts, axis=0) <= MAX_EXTENT):
        return
    mid = np.median(pts, axis=0)
    far = max(range(len(lanes)), key=lambda i: float(np.abs(lanes[i].centerline - mid).max()))
    raise MapError(
        f"lanes span {np.ptp(pts, axis=0).max():.3g} m, more than {MAX_EXTENT:g} m; farthest from the rest "
        "(corrupt coordinate, width or offset?)",
        path,
        lanes[far].source_id,
    )


class OpenDriveLoader:
    """Load an OpenDRIVE map into a compiled `RoadMap` (constructor = Hydra config schema).

    Args:
        path: The .xodr file.
        sample_step: Longest distance between samples along a road [m].
        default_speed_limit: Speed limit where the file gives none [m/s].
        max_segment_length: Longest observed road segment after compilation [m].

    Raises:
        ConfigError: A non-positive or non-finite numeric argument (checked here, nothing is
            read until `load`).
    """

    def __init__(
        self,
        path: str | Path,
        sample_step: float = 1.0,
        default_speed_limit: float = DEFAULT_SPEED_LIMIT,
        max_segment_length: float = 10.0,
    ) -> None:
        self.path = str(path)
        self.sample_step = float(sample_step)
        self.default_speed_limit = float(default_speed_limit)
        self.max_segment_length = float(max_segment_length)
        for name in ("sample_step", "default_speed_limit", "max_segment_length"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ConfigError(f"OpenDriveLoader {name}={value!r}: expected a positive finite number")

    def load(self) -> RoadMap:
        """Read, validate and compile the map."""
        elements = read_opendrive(self.path, self.sample_step, self.default_speed_limit)
        return compile_map(elements, max_segment_length=self.max_segment_length)
