"""sha256 of every env buffer over a rollout: the bit-identity check of refactors that must not
change the paper configuration (docs/benchmarks.md "Observation encoders").

Runs the paper configuration (default spawner, paper encoder, 32 worlds) for `--steps` steps
with fixed random actions at 1 and 2 threads, on the bundled town and, when it exists, on the
Tartu map of ../shared/maps, and prints one digest per (map, threads): the sha256 of the
concatenation of every buffer after every step. Only APIs that older trees have, so the same
script measures a baseline tree:

    PYTHONPATH=/tmp/base python benchmarks/obs_digests.py --tree /tmp/base
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import sys
from pathlib import Path


def digest(spec: str, threads: int, steps: int, worlds: int) -> str:
    """sha256 over all buffers after every step of one rollout."""
    import numpy as np

    from selfplaydrive.maps.loader import load_map
    from selfplaydrive.scenario.spawner import PaperSpawner
    from selfplaydrive.sim.vec_env import VecEnv

    env = VecEnv(load_map(spec), PaperSpawner(), worlds, seed=0, num_threads=threads)
    acts = np.random.default_rng(0).integers(0, [7, 13], size=(steps, env.num_agents, 2))
    h = hashlib.sha256()
    env.reset(0)
    for k in range(steps):
        env.step(acts[k])
        for name in sorted(env.buffers):
            h.update(np.ascontiguousarray(env.buffers[name]).tobytes())
    return h.hexdigest()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--tree", default=str(Path(__file__).resolve().parents[1]), help="tree whose package runs")
    p.add_argument("--steps", type=int, default=400)
    p.add_argument("--worlds", type=int, default=32)
    args = p.parse_args()
    sys.path.insert(0, str(Path(args.tree).resolve()))
    import selfplaydrive

    maps = ["default"]
    tartu = Path("../shared/maps/tartu_lanelet2/tartu_demo_l.osm")
    if tartu.exists():
        maps.append(str(tartu.resolve()))
    out = {"package": os.path.dirname(selfplaydrive.__file__), "digests": {}}
    for spec in maps:
        for threads in (1, 2):
            key = f"{Path(spec).stem} threads={threads}"
            out["digests"][key] = digest(spec, threads, args.steps, args.worlds)
            print(key, out["digests"][key], flush=True)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
