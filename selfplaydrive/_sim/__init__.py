"""Private Cython kernels: nogil, struct-of-arrays, parallel over worlds. Not a public API.

OpenMP threads spin briefly, then sleep, between parallel regions unless the user chose a
policy: GNU libgomp's default spins ~300,000 rounds (milliseconds) after every step, and a
worker spinning that long steals the core that Python (action sampling, the trainer) needs
between steps, which made 2 threads slower than 1 on 2 cores; sleeping at once
(`OMP_WAIT_POLICY=passive`) costs a wake-up per step instead (2 threads gave 0.81-0.91M
agent-steps/s in `selfplaydrive bench`, against 0.95-1.06M with 20,000 rounds, about half a
millisecond: docs/benchmarks.md). The variables must be set before libgomp initialises, that
is before the first kernel module is imported; `OMP_WAIT_POLICY` or `GOMP_SPINCOUNT` in the
environment override the default.
"""

import os

if "OMP_WAIT_POLICY" not in os.environ:
    os.environ.setdefault("GOMP_SPINCOUNT", "20000")

SIMD_NAMES = ("c", "sse2", "avx2")


def requested_simd(want: str | None = None) -> int:
    """Level index of `want` ("c", "sse2", "avx2"), or of the SELFPLAYDRIVE_SIMD environment
    variable when `want` is None; -1 (the best available) when neither is given.

    Raises:
        ValueError: An unknown name.
    """
    if want is None:
        want = os.environ.get("SELFPLAYDRIVE_SIMD", "").strip().lower() or None
    if want is None:
        return -1
    if want not in SIMD_NAMES:
        raise ValueError(f"SELFPLAYDRIVE_SIMD / simd level: expected one of {SIMD_NAMES}, got {want!r}")
    return SIMD_NAMES.index(want)


def simd_level(want: str | None = None) -> str:
    """Choose the implementation of the kernels' inner loops (_sim/simd.h): "c", "sse2" or
    "avx2", capped at what the build and the CPU support; None: SELFPLAYDRIVE_SIMD when set,
    else the best available (the default at import). Every level gives bit-identical results;
    only speed differs. Call it only while no step runs. Returns the level in use."""
    from selfplaydrive._sim import observe, road

    level = requested_simd(want)
    got = {observe._set_simd(level), road._set_simd(level)}
    assert len(got) == 1
    return SIMD_NAMES[got.pop()]
