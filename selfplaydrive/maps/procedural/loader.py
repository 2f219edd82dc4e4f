"""`ProceduralTownLoader` (Hydra `_target_`) and the bundled default town (section 2.1).

The default town is committed as a compiled map (`maps/default_town.npz` at the repository
root, written by `selfplaydrive.maps.cache.save_roadmap`): loading it takes milliseconds and
every user trains on the very same arrays. It is regenerated with
``python -m selfplaydrive.maps.procedural --out maps/default_town.npz`` and a test checks that
regenerating gives identical arrays. Where the file is absent (a wheel install without the
repository's `maps/` folder) `load_default_map` generates the same town on the fly.
"""

from __future__ import annotations

import dataclasses
import os
import tempfile
import zipfile
from pathlib import Path

from selfplaydrive.maps.cache import load_roadmap, save_roadmap
from selfplaydrive.maps.compile import (
    DEFAULT_CELL_SIZE,
    DEFAULT_COLLINEAR_TOL,
    DEFAULT_MAX_SEGMENT_LENGTH,
    compile_map,
)
from selfplaydrive.maps.procedural.params import KMH, TownParams
from selfplaydrive.maps.procedural.town import check_seed, generate_town
from selfplaydrive.maps.roadmap import RoadMap

DEFAULT_SEED = 0
DEFAULT_MAP_NAME = "default_town"


class ProceduralTownLoader:
    """Map loader for a generated town: the constructor arguments are the config schema.

    Args:
        seed: Generator seed (non-negative integer).
        size ... sample_step: The `TownParams` fields, same names, units and defaults
            (see `TownParams` and docs/maps/procedural.md).
        max_segment_length: Longest observed road segment [m] (`compile_map`).
        collinear_tol: Simplification tolerance [m] (`compile_map`).
        cell_size: Spatial grid cell [m] (`compile_map`).

    Raises:
        ConfigError: On an invalid seed or parameter (checked here, before any work).
    """

    def __init__(
        self,
        seed: int = DEFAULT_SEED,
        size: float = 1600.0,
        block_size: float = 90.0,
        irregularity: float = 0.5,
        removed_street_share: float = 0.15,
        lanes_per_direction: int = 2,
        minor_lanes_per_direction: int = 1,
        main_road_every: int = 4,
        signalised_share: float = 0.2,
        priority_share: float = 0.5,
        num_roundabouts: int = 4,
        crosswalk_density: float = 0.4,
        left_turn_lane_share: float = 0.8,
        right_turn_lane_share: float = 0.3,
        turn_lane_length: float = 45.0,
        solid_line_length: float = 15.0,
        taper_length: float = 15.0,
        lane_width: float = 3.5,
        minor_lane_width: float = 3.25,
        roundabout_lane_width: float = 4.5,
        roundabout_radius: float = 16.0,
        shoulder: float = 0.5,
        corner_radius: float = 6.0,
        crosswalk_width: float = 4.0,
        main_speed_limit: float = 50.0 * KMH,
        minor_speed_limit: float = 40.0 * KMH,
        zone30_share: float = 0.5,
        zone30_speed_limit: float = 30.0 * KMH,
        roundabout_speed_limit: float = 30.0 * KMH,
        sample_step: float = 4.0,
        max_segment_length: float = DEFAULT_MAX_SEGMENT_LENGTH,
        collinear_tol: float = DEFAULT_COLLINEAR_TOL,
        cell_size: float = DEFAULT_CELL_SIZE,
    ) -> None:
        values = dict(locals())
        self.seed = check_seed(seed, "ProceduralTownLoader")
        self.params = TownParams(
            **{f.name: values[f.name] for f in dataclasses.fields(TownParams)}
        ).validate()
        self.compile_kwargs = {
            "max_segment_length": max_segment_length,
            "collinear_tol": collinear_tol,
            "cell_size": cell_size,
        }

    def load(self) -> RoadMap:
        """Generate the town and compile it."""
        return compile_map(generate_town(self.seed, self.params), **self.compile_kwargs)


def default_map_path() -> Path:
    """Where the bundled default town lives: `<repository>/maps/default_town.npz`."""
    return Path(__file__).resolve().parents[3] / "maps" / f"{DEFAULT_MAP_NAME}.npz"


def build_default_map() -> RoadMap:
    """Generate and compile the default town (seed `DEFAULT_SEED`, default `TownParams`)."""
    road_map = ProceduralTownLoader(seed=DEFAULT_SEED).load()
    return dataclasses.replace(road_map, name=DEFAULT_MAP_NAME)


def write_default_map(path: str | Path | None = None) -> Path:
    """Regenerate the default town and save it (default: `default_map_path()`).

    The file is a `save_roadmap` cache whose zip members are deflated (about 2 MB instead of
    4): `load_roadmap` reads it unchanged. Member timestamps are fixed, so regenerating an
    unchanged town rewrites the very same bytes.
    """
    target = Path(path) if path is not None else default_map_path()
    target.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=target.parent) as tmp:
        plain = save_roadmap(
            build_default_map(),
            Path(tmp) / "plain.npz",
            compile_params={"generator": "default town", "seed": DEFAULT_SEED},
        )
        packed = Path(tmp) / "packed.npz"
        with (
            zipfile.ZipFile(plain) as zin,
            zipfile.ZipFile(packed, "w", zipfile.ZIP_DEFLATED, compresslevel=9) as zout,
        ):
            for info in zin.infolist():
                member = zipfile.ZipInfo(info.filename, date_time=(1980, 1, 1, 0, 0, 0))
                member.compress_type = zipfile.ZIP_DEFLATED
                zout.writestr(member, zin.read(info.filename))
        os.replace(packed, target)
    return target


def load_default_map() -> RoadMap:
    """The bundled default town: the committed file, or the same town generated on the fly."""
    path = default_map_path()
    if path.exists():
        return load_roadmap(path)
    return build_default_map()
