"""The map-loader contract (paper section 2.1; docs/maps/README.md).

A loader turns one map source (a Lanelet2 .osm file, an OpenDRIVE .xodr file, a procedural
generator call ...) into a compiled `RoadMap`. It is the first component of an env and is
built from config with ``_target_`` (conf group ``map/``).
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

from selfplaydrive.maps.roadmap import RoadMap

__all__ = ["MapLoader"]


@runtime_checkable
class MapLoader(Protocol):
    """Anything with a ``load() -> RoadMap`` method.

    Contract every implementation keeps:

    - The constructor only stores and validates its arguments (path, projection, compile
      parameters such as ``max_segment_length`` [m]); it does no heavy work, so configs can
      be instantiated cheaply. Invalid arguments raise `ConfigError` listing valid values.
    - ``load()`` reads the source, builds `MapElements` and returns
      `selfplaydrive.maps.compile.compile_map(elements, ...)`, so every loader shares the same
      validation, recentring, segment cutting and spatial grid.
    - Lanes are directed (centerline in the direction of travel), right-hand traffic as the
      source encodes it; lengths are metres in a planar frame (x east, y north), and
      ``RoadMap.origin`` keeps the global position of the local (0, 0).
    - Bad input raises `MapError` naming the file and the offending element, never a bare
      exception, a crash or a hang.
    - ``load()`` is deterministic: the same source and arguments give identical arrays (the
      compiled-map cache in `selfplaydrive.maps.cache` relies on it).

    Caching is not the loader's job: `selfplaydrive.maps.loader.load_map` wraps file loaders
    with the compiled-map cache.
    """

    def load(self) -> RoadMap:
        """Read the source and return the compiled map."""
        ...
