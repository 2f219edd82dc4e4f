"""The ``selfplaydrive`` command line.

``main`` only picks the command and hands the rest of the argument list to that command's
function, so each command parses its own arguments: argparse here (``map``), Hydra overrides
and ``-m`` sweeps for ``train``, ``eval``, ``render`` and ``bench`` (selfplaydrive/hydra_app.py,
configs in selfplaydrive/conf/). Exit codes: 0 success, 1 a map/config/checkpoint error or a
missing optional dependency (one line on stderr; HYDRA_FULL_ERROR=1 shows the traceback), 2 bad
usage.

Examples::

    selfplaydrive map info ../shared/maps/tartu_lanelet2/tartu_demo_l.osm --json
    selfplaydrive map render default -o town.png --arrows
    selfplaydrive map render Town01.xodr -o crop.png --region -100 -100 100 100 --dpi 200
    selfplaydrive render driver=random steps=50 output=random.gif physics=bicycle
    selfplaydrive bench --json map=file map.spec=Town01.xodr
    selfplaydrive bench -m physics=bicycle,friction threads=[1]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

from selfplaydrive.errors import CheckpointError, ConfigError, MapError, MissingExtraError

if TYPE_CHECKING:  # the map stack (numpy, shapely ...) is imported only by the commands that need it
    from selfplaydrive.maps.roadmap import RoadMap

# errors that are the user's input or installation, reported in one line (not a traceback)
USER_ERRORS = (ConfigError, MapError, CheckpointError, MissingExtraError)

MAP_INFO_KEYS = (
    "lane_km",
    "num_lanes",
    "num_traffic_light_stop_lines",
    "num_stop_lines",
    "num_crosswalks",
    "road_edge_km",
    "bounds",
)


def map_stats(road_map: RoadMap) -> dict[str, object]:
    """The numbers ``selfplaydrive map info`` prints.

    Returns:
        lane_km: vehicle-lane centerline length [km] (`RoadMap.vehicle_lane_km`: bus lanes
        included, bicycle lanes excluded, bidirectional twins counted once); num_lanes: number
        of directed lanes of every kind; num_traffic_light_stop_lines, num_stop_lines (stop and
        yield), num_crosswalks; road_edge_km [km]; bounds: [xmin, ymin, xmax, ymax] [m] in the
        map's local frame.
    """
    m = road_map
    return {
        "lane_km": round(m.vehicle_lane_km(), 4),
        "num_lanes": len(m.lanes),
        "num_traffic_light_stop_lines": len(m.light_lines),
        "num_stop_lines": len(m.stop_lines),
        "num_crosswalks": len(m.crosswalks),
        "road_edge_km": round(float(m.road_edges.lengths().sum()) / 1000.0, 4),
        "bounds": [round(float(v), 3) for v in m.bounds],
    }


def _add_load_args(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "path",
        help="map: .osm (Lanelet2), .xodr (OpenDRIVE), .npz (compiled), "
        "'default' or 'procedural:seed=S,size=M'",
    )
    p.add_argument(
        "--cache-dir",
        default=None,
        help="compiled-map cache folder (default $SELFPLAYDRIVE_CACHE_DIR or ~/.cache/selfplaydrive/maps)",
    )
    p.add_argument("--rebuild", action="store_true", help="recompile the map and overwrite its cache")
    p.add_argument("--no-cache", action="store_true", help="compile without reading or writing the cache")


def _load(args: argparse.Namespace) -> RoadMap:
    from selfplaydrive.maps.loader import load_map

    return load_map(args.path, cache_dir=args.cache_dir, rebuild=args.rebuild, use_cache=not args.no_cache)


def _map_info(args: argparse.Namespace) -> int:
    road_map = _load(args)
    stats = map_stats(road_map)
    if args.json:
        print(json.dumps(stats))
        return 0
    print(f"map      {road_map.name}  ({road_map.source or 'generated'})")
    print(f"origin   ({road_map.origin[0]:.3f}, {road_map.origin[1]:.3f}) [m], crs: {road_map.crs}")
    for key in MAP_INFO_KEYS:
        print(f"{key:30s} {stats[key]}")
    print(f"{'num_signal_groups':30s} {road_map.num_signal_groups}")
    print(f"{'num_road_segments':30s} {len(road_map.segments)}")
    return 0


def _map_render(args: argparse.Namespace) -> int:
    from selfplaydrive.render.map_render import render_map

    road_map = _load(args)
    try:
        out = render_map(road_map, args.output, arrows=args.arrows, region=args.region, dpi=args.dpi)
    except ValueError as exc:  # bad region / dpi: a usage error, say which value
        print(f"selfplaydrive map render: error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {out}")
    return 0


def _map_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="selfplaydrive map", description="Inspect and draw road maps.")
    sub = parser.add_subparsers(dest="action", required=True, metavar="{info,render}")
    info = sub.add_parser("info", help="print map statistics")
    _add_load_args(info)
    info.add_argument(
        "--json", action="store_true", help="one JSON object with keys " + ", ".join(MAP_INFO_KEYS)
    )
    info.set_defaults(func=_map_info)
    render = sub.add_parser("render", help="draw the map top-down to an image")
    _add_load_args(render)
    render.add_argument("-o", "--output", required=True, help="output image, e.g. map.png")
    render.add_argument(
        "--arrows", action="store_true", help="draw travel direction, dead ends, gapped links"
    )
    render.add_argument(
        "--region",
        nargs=4,
        type=float,
        metavar=("XMIN", "YMIN", "XMAX", "YMAX"),
        help="crop [m] in the map's local frame (see 'map info' bounds)",
    )
    render.add_argument("--dpi", type=int, default=150, help="dots per inch (default 150)")
    render.set_defaults(func=_map_render)
    return parser


def cmd_map(argv: Sequence[str]) -> int:
    """``selfplaydrive map {info,render} ...``."""
    args = _map_parser().parse_args(list(argv))
    try:
        return args.func(args)
    except USER_ERRORS as exc:
        if os.environ.get("HYDRA_FULL_ERROR") == "1":
            raise
        print(f"selfplaydrive map {args.action}: error: {exc}", file=sys.stderr)
        return 1


def cmd_bench(argv: Sequence[str]) -> int:
    """``selfplaydrive bench [hydra overrides] [json=true|--json] [-m]``: simulator throughput
    (conf/bench.yaml, sim/bench.py)."""
    from selfplaydrive.hydra_app import cmd_bench as bench

    return bench(argv)


def cmd_render(argv: Sequence[str]) -> int:
    """``selfplaydrive render [hydra overrides] [-m]``: draw an episode (conf/render.yaml)."""
    from selfplaydrive.hydra_app import cmd_render as render

    return render(argv)


# command name -> (function taking the remaining argv and returning an exit code, one-line help)
def cmd_train(argv: Sequence[str]) -> int:
    """``selfplaydrive train [hydra overrides] [-m]``: PPO training (docs/training.md)."""
    from selfplaydrive.hydra_app import cmd_train as train

    return train(argv)


def cmd_eval(argv: Sequence[str]) -> int:
    """``selfplaydrive eval [hydra overrides]``: suites and long-form evaluation (docs/analyses.md)."""
    from selfplaydrive.hydra_app import cmd_eval as evaluate

    return evaluate(argv)


COMMANDS: dict[str, tuple[Callable[[Sequence[str]], int], str]] = {
    "train": (cmd_train, "train a policy (Hydra overrides, -m for sweeps)"),
    "eval": (cmd_eval, "rule-adherence suites and long-form evaluation (Hydra overrides)"),
    "map": (cmd_map, "inspect (info) and draw (render) road maps"),
    "render": (cmd_render, "drive an episode and draw it top-down: PNG frames, GIF, MP4 (Hydra overrides)"),
    "bench": (cmd_bench, "simulator throughput in agent-steps/s (Hydra overrides, --json)"),
}


def _usage() -> str:
    lines = ["usage: selfplaydrive COMMAND [ARGS ...]", "", "commands:"]
    lines += [f"  {name:10s} {help_}" for name, (_, help_) in COMMANDS.items()]
    lines += ["", "'selfplaydrive COMMAND --help' shows a command's arguments."]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``selfplaydrive`` script; returns the exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(_usage(), file=sys.stdout if argv else sys.stderr)
        return 0 if argv else 2
    if argv[0] == "--version":
        from selfplaydrive import __version__

        print(f"selfplaydrive {__version__}")
        return 0
    if argv[0] not in COMMANDS:
        print(
            f"selfplaydrive: unknown command {argv[0]!r}; valid choices: {', '.join(COMMANDS)}\n\n{_usage()}",
            file=sys.stderr,
        )
        return 2
    try:
        return COMMANDS[argv[0]][0](argv[1:])
    except USER_ERRORS as exc:  # e.g. importing a command's module needs a missing extra
        if os.environ.get("HYDRA_FULL_ERROR") == "1":
            raise
        print(f"selfplaydrive {argv[0]}: error: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
