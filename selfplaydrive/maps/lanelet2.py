"""Lanelet2 map loader (OSM XML) -> `MapElements` -> `RoadMap` (paper section 2.1).

The paper trains on the Lanelet2 HD map of Tartu. This loader reads such files with the
standard-library XML parser plus numpy/shapely/scipy:

1. `lanelet2_osm.read_osm`: nodes, ways, relations; planar coordinates from local_x/local_y
   (Tartu: L-EST97 minus (650000, 6465000), recognised and recorded in `frame_origin`) or a
   local transverse Mercator projection of lat/lon.
2. `lanelet2_lanes`: bounds oriented like the official Lanelet2 loader, directed lanes (two
   twins for one_way=no), centerlines, widths, speed limits, the lane graph.
3. `lanelet2_regulatory`: traffic lights, stop/yield lines, crosswalks.
4. `lanelet2_area`: road edges (mapped lines + lanelet-union outline), junction flags.

What is read and what is ignored is documented in docs/maps/lanelet2.md.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import shapely
from shapely.geometry import LineString

from selfplaydrive.errors import ConfigError, MapError
from selfplaydrive.maps.compile import DEFAULT_MAX_SEGMENT_LENGTH, compile_map
from selfplaydrive.maps.elements import MapElements
from selfplaydrive.maps.lanelet2_area import junction_lanelets, lanelet_polygon, mapped_edges, outline_edges
from selfplaydrive.maps.lanelet2_lanes import build_lanes, oriented_bounds, to_elements
from selfplaydrive.maps.lanelet2_osm import read_osm
from selfplaydrive.maps.lanelet2_regulatory import crosswalks, stop_lines, traffic_lights
from selfplaydrive.maps.roadmap import RoadMap

DEFAULT_SPEED_LIMIT = 50.0 / 3.6  # [m/s] urban default (Lanelet2's German/Estonian urban road)

__all__ = ["DEFAULT_SPEED_LIMIT", "Lanelet2Loader", "read_lanelet2"]


def read_lanelet2(
    path: str | Path, default_speed_limit: float = DEFAULT_SPEED_LIMIT, outline_edges_enabled: bool = True
) -> MapElements:
    """Read a Lanelet2 OSM XML file into `MapElements`.

    Args:
        path: The .osm file.
        default_speed_limit: Speed limit [m/s] of lanes whose lanelet states none.
        outline_edges_enabled: Add the lanelet-union outline as road edges where no mapped
            edge line is near (see `lanelet2_area`).

    Returns:
        Lanes (directed, with lane graph), road edges, stop lines, traffic lights, crosswalks in
        a planar frame [m]; `frame_origin`/`crs` tell where that frame sits.

    Raises:
        MapError: Malformed file, dangling references, bad coordinates, degenerate lanelets, or
            a map without lanelets; the message names the file and the element.
    """
    spath = str(path)
    if not (np.isfinite(default_speed_limit) and default_speed_limit > 0):
        raise MapError(
            f"default_speed_limit must be a positive number [m/s], got {default_speed_limit}", spath
        )
    osm = read_osm(spath)
    rels = [r for r in osm.relations.values() if r.tags.get("type") == "lanelet"]
    if not rels:
        raise MapError("the map has no lanelet relations (type=lanelet); expected a Lanelet2 map", spath)
    bounds = {r.id: oriented_bounds(osm, r) for r in sorted(rels, key=lambda r: r.id)}
    lanes = build_lanes(osm, bounds, float(default_speed_limit))
    if not lanes:
        raise MapError("the map has no lanelets that vehicles, buses or bicycles may use", spath)
    polygons = {lid: lanelet_polygon(bounds[lid]) for lid in sorted({ln.lanelet for ln in lanes})}
    elements = to_elements(osm, lanes)
    junction = junction_lanelets(osm, lanes, polygons)
    for el, ln in zip(elements, lanes, strict=True):
        el.in_junction = ln.lanelet in junction
    tree = shapely.STRtree([LineString(ln.center) for ln in lanes])
    lights, light_ways = traffic_lights(osm, lanes, tree)
    edges = mapped_edges(osm)
    if outline_edges_enabled:
        edges += outline_edges(list(polygons.values()), edges)
    return MapElements(
        name=Path(spath).stem,
        source=spath,
        frame_origin=osm.frame_origin,
        crs=osm.crs,
        lanes=elements,
        road_edges=edges,
        stop_lines=stop_lines(osm, lanes, tree, light_ways),
        traffic_lights=lights,
        crosswalks=crosswalks(osm, bounds),
    )


class Lanelet2Loader:
    """Build a `RoadMap` from a Lanelet2 file; the constructor arguments are its config schema
    (Hydra `_target_: selfplaydrive.maps.lanelet2.Lanelet2Loader`).

    Args:
        path: The .osm file.
        default_speed_limit: Speed limit [m/s] where the map states none.
        max_segment_length: Longest observed road segment [m] (paper section 2.5).

    Raises:
        ConfigError: A non-positive or non-finite speed limit or segment length.
    """

    def __init__(
        self,
        path: str,
        default_speed_limit: float = DEFAULT_SPEED_LIMIT,
        max_segment_length: float = DEFAULT_MAX_SEGMENT_LENGTH,
    ) -> None:
        for name, value in (
            ("default_speed_limit", default_speed_limit),
            ("max_segment_length", max_segment_length),
        ):
            if not (isinstance(value, (int, float)) and np.isfinite(value) and value > 0):
                raise ConfigError(f"Lanelet2Loader.{name} must be a positive finite number, got {value!r}")
        self.path = str(path)
        self.default_speed_limit = float(default_speed_limit)
        self.max_segment_length = float(max_segment_length)

    def load(self) -> RoadMap:
        """Read and compile the map."""
        elements = read_lanelet2(self.path, self.default_speed_limit)
        return compile_map(elements, max_segment_length=self.max_segment_length)
