"""Spawner benchmark: per-map preparation and the cost of one world reset (paper section 2.2).

Usage (from the repository root)::

    python benchmarks/bench_spawn.py                          # bundled default town
    python benchmarks/bench_spawn.py --map ../shared/maps/tartu_lanelet2/tartu_demo_l.osm
    python benchmarks/bench_spawn.py --resets 2000 --repeat 7

Prints the time of `PaperSpawner.prepare` (per-map tables, once) and, for `PaperSpawner.sample`
with the paper's settings (32 agents, 48 static vehicles, 8 pedestrians, 8 waypoints), the
median over `--repeat` blocks of wall-clock and process CPU time per reset, a per-step
breakdown, and how full the worlds are. Target: about 0.3 ms per `sample` on one core, the
spawner's share of the 1 ms budget of a whole world reset (sample, pack, first observation).
On a shared machine the wall time includes waiting for a core, so the CPU time is the fairer
number; the load average is printed beside it.
"""

from __future__ import annotations

import argparse
import functools
import os
import statistics
import time
import warnings

import numpy as np

from selfplaydrive.maps.loader import load_map
from selfplaydrive.scenario.spawner import PaperSpawner

TARGET_MS = 0.3  # [ms] per sample: the spawner's share of a 1 ms world reset
IDLE_OP_US = 0.5  # [us] the calibration op on an idle desktop core, for the scaled estimate
STEPS = ("_agents", "_waypoints", "_statics")


def _timed_steps(sp: PaperSpawner, totals: dict[str, float]) -> None:
    """Wrap the spawner's steps (instance attributes shadow the methods) to sum CPU time."""

    def wrap(name: str, fn):
        @functools.wraps(fn)
        def inner(*args, **kwargs):
            t0 = time.process_time()
            out = fn(*args, **kwargs)
            totals[name] = totals.get(name, 0.0) + time.process_time() - t0
            return out

        return inner

    for name in STEPS:
        setattr(sp, name, wrap(name, getattr(sp, name)))
    for attr in ("pedestrians", "lights", "conditioning", "hidden"):
        obj = getattr(sp, attr)
        obj.sample = wrap(attr, obj.sample)


def _calibration_us() -> float:
    """Best time [us] of one tiny NumPy op: most of a reset is many such calls, so this puts the
    reset time in context across machines (about 0.5 us on an idle desktop core)."""
    a = np.zeros(64)
    best = np.inf
    for _ in range(5):
        t0 = time.perf_counter()
        for _ in range(20000):
            a + 1.0
        best = min(best, (time.perf_counter() - t0) / 20000 * 1e6)
    return best


def bench(spec: str, resets: int, repeat: int, seed: int) -> None:
    road_map = load_map(spec)
    sp = PaperSpawner()
    t0 = time.perf_counter()
    index = sp.prepare(road_map)
    prep = time.perf_counter() - t0
    print(
        f"map {road_map.name}: {road_map.vehicle_lane_km():.1f} km of vehicle lanes, "
        f"{len(road_map.lanes)} lanes"
    )
    print(
        f"prepare (per-map tables, once): {prep * 1e3:.0f} ms; {len(index.centres)} region centres, "
        f"{len(index.spawn.lane)} spawn chunks, {len(index.roadside.lane)} roadside chunks, "
        f"{len(index.crossings.start)} crossings, {len(index.crosswalks.start)} crosswalks"
    )
    rng = np.random.default_rng(seed)
    wall, cpu, fill = [], [], []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # shortfall warnings are counted below, not printed
        for _ in range(max(resets // 10, 1)):  # warm-up
            sp.sample(road_map, rng)
        for _ in range(repeat):
            w0, c0 = time.perf_counter(), time.process_time()
            for _ in range(resets):
                sc = sp.sample(road_map, rng)
                fill.append(int(sc.agent_valid.sum()))
            wall.append((time.perf_counter() - w0) / resets * 1e3)
            cpu.append((time.process_time() - c0) / resets * 1e3)
        totals: dict[str, float] = {}
        _timed_steps(sp, totals)
        for _ in range(resets):
            sp.sample(road_map, rng)
    cpu_ms = statistics.median(cpu)
    print(
        f"reset: {cpu_ms:.3f} ms CPU (median of {repeat} x {resets}), {statistics.median(wall):.3f} ms wall; "
        f"{cpu_ms / TARGET_MS:.2f}x the ~{TARGET_MS} ms target"
    )
    cal = _calibration_us()
    print(
        f"  machine: small NumPy op (64 floats + 1) takes {cal:.2f} us here; scaled to "
        f"{IDLE_OP_US} us per op (idle desktop core) the reset would cost "
        f"~{cpu_ms * IDLE_OP_US / cal:.2f} ms (a rough estimate)"
    )
    print(f"  load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    print(
        "  breakdown (CPU ms per reset, timing wrappers add a little): "
        + ", ".join(f"{k.strip('_')} {v / resets * 1e3:.3f}" for k, v in totals.items())
    )
    fill_arr = np.array(fill)
    print(
        f"agents per world: mean {fill_arr.mean():.2f} of {sp.num_agents}, "
        f"full in {np.mean(fill_arr == sp.num_agents):.0%}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--map", default="default", help="map spec for selfplaydrive.maps.loader.load_map")
    parser.add_argument("--resets", type=int, default=500, help="resets per timed block")
    parser.add_argument("--repeat", type=int, default=5, help="timed blocks (the median is reported)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    bench(args.map, args.resets, args.repeat, args.seed)


if __name__ == "__main__":
    main()
