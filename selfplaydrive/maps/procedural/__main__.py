"""Regenerate the bundled default town, or write any generated town.

python -m selfplaydrive.maps.procedural --out maps/default_town.npz
python -m selfplaydrive.maps.procedural --seed 7 --size 800 --out /tmp/town7.npz --png /tmp/town7.png
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from selfplaydrive.maps.cache import load_roadmap, save_roadmap
from selfplaydrive.maps.procedural.loader import (
    DEFAULT_SEED,
    ProceduralTownLoader,
    default_map_path,
    write_default_map,
)


def main(argv: list[str] | None = None) -> None:
    """Command-line entry point (see module docstring)."""
    ap = argparse.ArgumentParser(
        prog="python -m selfplaydrive.maps.procedural", description=__doc__.split("\n")[0]
    )
    ap.add_argument("--out", type=Path, default=default_map_path(), help="compiled map .npz to write")
    ap.add_argument("--seed", type=int, default=None, help="town seed (default: the default town)")
    ap.add_argument("--size", type=float, default=None, help="town size [m] (with --seed)")
    ap.add_argument("--png", type=Path, default=None, help="also render the map to this PNG")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    if args.seed is None and args.size is None:
        write_default_map(args.out)
        road_map = load_roadmap(args.out)
    else:
        kwargs = {"seed": DEFAULT_SEED if args.seed is None else args.seed}
        if args.size is not None:
            kwargs["size"] = args.size
        road_map = ProceduralTownLoader(**kwargs).load()
        params = {"generator": "ProceduralTownLoader", **kwargs}
        save_roadmap(road_map, args.out, compile_params=params)
    elapsed = time.perf_counter() - t0
    print(
        f"{args.out}: {road_map.vehicle_lane_km():.2f} lane-km, {len(road_map.lanes)} lanes, "
        f"{len(road_map.light_group)} lights, {len(road_map.stop_kind)} stop lines, "
        f"{len(road_map.crosswalks)} crosswalks; generated, compiled and saved in {elapsed:.2f} s"
    )
    if args.png is not None:
        from selfplaydrive.render.map_render import render_map

        render_map(road_map, args.png, size=16)


if __name__ == "__main__":
    main()
