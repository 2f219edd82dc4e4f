"""Private Cython kernels: nogil, struct-of-arrays, parallel over worlds. Not a public API.

OpenMP threads wait passively (sleep) between parallel regions unless the user chose a policy:
the default GNU policy spins for a while after every step, and a spinning worker steals the
core that Python (action sampling, the trainer) needs between steps, which made 2 threads
slower than 1 on 2 cores. The variable must be set before libgomp initialises, that is before
the first kernel module is imported; `OMP_WAIT_POLICY=active` in the environment overrides it.
"""

import os

os.environ.setdefault("OMP_WAIT_POLICY", "passive")

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
