"""Simulator throughput benchmark; see selfplaydrive/sim/bench.py.

Usage: python benchmarks/bench_sim.py [--json] [--map PATH] [--threads 1,2] [--worlds 32]
Run it pinned (taskset -c 0,1) and on an otherwise idle machine: other processes on the same
cores change the numbers.
"""

import sys

from selfplaydrive.sim.bench import main

if __name__ == "__main__":
    main(sys.argv[1:])
