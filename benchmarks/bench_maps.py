"""Map benchmark: compile time, compiled-cache load time, road-segment radius queries.

Usage (from the repository root)::

    python benchmarks/bench_maps.py                      # ../shared/maps Tartu Lanelet2 map
    python benchmarks/bench_maps.py --map ../shared/maps/carla_opendrive/Town04.xodr
    python benchmarks/bench_maps.py --map default --queries 200000 --radius 50

Targets (docs/benchmarks.md): compile of tartu_demo_l.osm < 2 s, cache load < 50 ms, mean
100 m radius query < 2 us. The query numbers time `selfplaydrive._sim.spatial.query_radius_batch`
(the nogil grid kernel the simulator uses) over random points uniform inside the map bounds (as
specified) and along lane centerlines (where agents are; most of a city's bounding box is empty),
collecting every index found; "count only" keeps one index per query, isolating the grid scan
from writing the results.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from selfplaydrive._sim.spatial import query_radius_batch
from selfplaydrive.maps.cache import load_roadmap, save_roadmap
from selfplaydrive.maps.loader import load_map
from selfplaydrive.maps.roadmap import RoadMap, SegmentType

DEFAULT_MAP = Path(__file__).resolve().parents[2] / "shared" / "maps" / "tartu_lanelet2" / "tartu_demo_l.osm"
TARGET_COMPILE_S = 2.0
TARGET_LOAD_MS = 50.0
TARGET_QUERY_US = 2.0


def _verdict(ok: bool) -> str:
    return "ok" if ok else "MISSED"


def bench_compile(spec: str, repeat: int) -> tuple[RoadMap, list[float]]:
    """Parse + compile from source, no cache; returns the map and each run's seconds."""
    times, road_map = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        road_map = load_map(spec, use_cache=False)
        times.append(time.perf_counter() - t0)
    assert road_map is not None
    return road_map, times


def bench_cache(road_map: RoadMap, repeat: int) -> tuple[list[float], int]:
    """Save once, then time `load_roadmap`; returns each load's seconds and the file size [B]."""
    with tempfile.TemporaryDirectory() as tmp:
        path = save_roadmap(road_map, Path(tmp) / "bench.npz")
        load_roadmap(path)  # warm the OS page cache and the type-hint cache, like a real second run
        times = []
        for _ in range(repeat):
            t0 = time.perf_counter()
            load_roadmap(path)
            times.append(time.perf_counter() - t0)
        return times, path.stat().st_size


def _run_queries(
    road_map: RoadMap, pts: np.ndarray, radius: float, cap: int, chunk: int
) -> tuple[float, np.ndarray]:
    counts = np.empty(len(pts), dtype=np.int32)
    t0 = time.perf_counter()
    for i in range(0, len(pts), chunk):
        c, _ = query_radius_batch(road_map, pts[i : i + chunk], radius, cap)
        counts[i : i + chunk] = c
    return time.perf_counter() - t0, counts


def random_points(road_map: RoadMap, num: int, seed: int, on_lanes: bool) -> np.ndarray:
    """(num, 2) float32 [m]: uniform in the map bounds, or uniform along lane centerlines (where
    agents are: the simulator's case)."""
    rng = np.random.default_rng(seed)
    if not on_lanes:
        lo, hi = road_map.bounds[:2].astype(np.float64), road_map.bounds[2:].astype(np.float64)
        return rng.uniform(lo, hi, size=(num, 2)).astype(np.float32)
    seg = road_map.segments
    lane = np.flatnonzero(seg.type == SegmentType.LANE_CENTER)
    w = seg.length[lane].astype(np.float64)
    pick = lane[rng.choice(len(lane), size=num, p=w / w.sum())]
    t = rng.uniform(size=(num, 1))
    return (seg.start[pick] + t * (seg.end[pick] - seg.start[pick])).astype(np.float32)


def bench_queries(road_map: RoadMap, pts: np.ndarray, radius: float, chunk: int = 1024) -> dict[str, float]:
    """Time radius queries at `pts` [m]; chunks keep the (chunk, cap) result buffer in cache."""
    num = len(pts)
    _, counts = _run_queries(road_map, pts, radius, 1, chunk)  # warm-up, and the largest result
    cap = max(1, int(counts.max()))
    t_all, counts_all = _run_queries(road_map, pts, radius, cap, chunk)
    t_count, _ = _run_queries(road_map, pts, radius, 1, chunk)
    assert np.array_equal(counts, counts_all)
    return {
        "us_per_query": t_all / num * 1e6,
        "queries_per_s": num / t_all,
        "us_per_query_count_only": t_count / num * 1e6,
        "mean_found": float(counts.mean()),
        "max_found": float(cap),
        "share_empty": float(np.mean(counts == 0)),
    }


def main(argv: list[str] | None = None) -> int:
    """Run the three measurements and print them with the targets."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--map", default=str(DEFAULT_MAP), help="anything load_map accepts (default: Tartu)")
    p.add_argument("--repeat", type=int, default=3, help="compile repetitions (default 3)")
    p.add_argument("--load-repeat", type=int, default=20, help="cache-load repetitions (default 20)")
    p.add_argument("--queries", type=int, default=100_000, help="number of radius queries (default 100k)")
    p.add_argument("--radius", type=float, default=100.0, help="query radius [m] (default 100)")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    if args.map == str(DEFAULT_MAP) and not DEFAULT_MAP.exists():
        print(
            f"{DEFAULT_MAP} not found: pass --map PATH (a Lanelet2 .osm, OpenDRIVE .xodr or 'default')",
            file=sys.stderr,
        )
        return 2

    road_map, t_comp = bench_compile(args.map, args.repeat)
    print(
        f"map            {road_map.name}: {road_map.vehicle_lane_km():.2f} lane-km, "
        f"{len(road_map.lanes)} lanes, "
        f"{len(road_map.segments)} segments, grid {road_map.grid.shape[0]}x{road_map.grid.shape[1]} "
        f"cells of {road_map.grid.cell_size:g} m"
    )
    best = min(t_comp)
    print(
        f"compile        min {best:.3f} s, median {statistics.median(t_comp):.3f} s over {len(t_comp)} runs "
        f"(parse + compile, no cache)  target < {TARGET_COMPILE_S:g} s: {_verdict(best < TARGET_COMPILE_S)}"
    )
    t_load, size = bench_cache(road_map, args.load_repeat)
    med_ms = statistics.median(t_load) * 1e3
    print(
        f"cache load     median {med_ms:.2f} ms, min {min(t_load) * 1e3:.2f} ms over {len(t_load)} loads "
        f"({size / 1e6:.2f} MB file)  target < {TARGET_LOAD_MS:g} ms: {_verdict(med_ms < TARGET_LOAD_MS)}"
    )
    for on_lanes, where in ((False, "uniform in the map bounds"), (True, "on lane centerlines")):
        q = bench_queries(road_map, random_points(road_map, args.queries, args.seed, on_lanes), args.radius)
        print(
            f"radius query   r = {args.radius:g} m, {args.queries} random points {where}: "
            f"{q['us_per_query']:.3f} us/query ({q['queries_per_s'] / 1e6:.2f} M queries/s), "
            f"count only {q['us_per_query_count_only']:.3f} us/query; "
            f"mean {q['mean_found']:.1f} segments found (max {q['max_found']:.0f}, "
            f"{q['share_empty'] * 100:.0f}% find none)  "
            f"target < {TARGET_QUERY_US:g} us: {_verdict(q['us_per_query'] < TARGET_QUERY_US)}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
