"""Procedural town generator and the bundled default town (paper section 2.1; docs/maps/procedural.md).

A town is a jittered grid of streets with 3- and 4-way intersections, multi-lane main roads
with turn pockets, roundabouts, signalised intersections, stop and yield lines and crosswalks, in
right-hand traffic, with a legal lane graph that is strongly connected.

    from selfplaydrive.maps.procedural import TownParams, generate_town, load_default_map
    elements = generate_town(seed=3, params=TownParams(size=800.0))
    road_map = load_default_map()
"""

from selfplaydrive.maps.procedural.loader import (
    DEFAULT_SEED,
    ProceduralTownLoader,
    build_default_map,
    default_map_path,
    load_default_map,
    write_default_map,
)
from selfplaydrive.maps.procedural.params import TownParams
from selfplaydrive.maps.procedural.town import generate_town

__all__ = [
    "DEFAULT_SEED",
    "ProceduralTownLoader",
    "TownParams",
    "build_default_map",
    "default_map_path",
    "generate_town",
    "load_default_map",
    "write_default_map",
]
