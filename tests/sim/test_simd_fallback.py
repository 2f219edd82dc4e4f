"""The SIMD levels (plain C, SSE2, AVX2; _sim/simd.h) of the row writers, the road scan and
the collision / object pre-tests (_sim/rows.h, scan.h, near.h) against a build without SSE2
(the code used where SSE2 is missing, e.g. ARM): bit-identical results."""

from __future__ import annotations

import platform
import shutil
import subprocess
from pathlib import Path

import pytest

SIM = Path(__file__).resolve().parents[2] / "selfplaydrive" / "_sim"
C = Path(__file__).resolve().parent / "c"


@pytest.mark.skipif(platform.machine() not in ("x86_64", "AMD64"), reason="SSE2 path is x86-64 only")
def test_sse2_and_plain_c_builds_agree(tmp_path):
    cc = shutil.which("gcc") or shutil.which("cc")
    if cc is None:
        pytest.skip("no C compiler to build the check")
    flags = ["-O3", "-ffp-contract=off", f"-I{SIM}", "-c", str(C / "wrap.c")]
    subprocess.run([cc, *flags, "-o", str(tmp_path / "sse.o"), "-DNAME(x)=sse_##x"], check=True)
    subprocess.run([cc, *flags, "-U__SSE2__", "-o", str(tmp_path / "c.o"), "-DNAME(x)=c_##x"], check=True)
    exe = tmp_path / "check"
    subprocess.run(
        [
            cc,
            "-O2",
            str(C / "simd_vs_c.c"),
            str(tmp_path / "sse.o"),
            str(tmp_path / "c.o"),
            "-lm",
            "-o",
            str(exe),
        ],
        check=True,
    )
    out = subprocess.run([str(exe)], capture_output=True, text=True)
    assert out.returncode == 0, out.stdout
    assert out.stdout.startswith("mismatches 0;")
    assert int(out.stdout.split("levels ")[1].split(";")[0]) >= 2  # plain C and SSE2 at least
    inner, shell = out.stdout.split("inner ")[1].split(" shell ")
    a, b = inner.split("/")
    c, d = shell.split("/")
    assert a == b and c == d.strip() and int(a) > 0 and int(c) > 0  # scan counts match a direct count


def _rollout(level: str, steps: int = 60) -> tuple[bytes, ...]:
    import warnings

    import numpy as np

    from selfplaydrive._sim import simd_level
    from selfplaydrive.maps.loader import load_map
    from selfplaydrive.scenario import PaperSpawner
    from selfplaydrive.sim import VecEnv

    assert simd_level(level) == level
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the spawner may place fewer agents on the town map
        env = VecEnv(load_map("default"), PaperSpawner(), 3, seed=4, terminated_vehicle="obstacle")
        env.reset(4)
        rng = np.random.default_rng(4)
        out = []
        for _ in range(steps):
            env.step(rng.integers(0, [7, 13], size=(env.num_agents, 2)))
            b = env.buffers
            out.append(b["obs"].tobytes() + b["terms"].tobytes() + b["road_idx"].tobytes())
    return tuple(out)


def test_every_simd_level_gives_the_same_rollout():
    """The whole simulator (bundled town, paper spawner: 200 road rows, shells selected every
    step) at each SIMD level the machine has: bit-identical observations, rewards and road
    indices, row order included."""
    from selfplaydrive._sim import SIMD_NAMES, simd_level

    best = simd_level()
    try:
        levels = SIMD_NAMES[: SIMD_NAMES.index(best) + 1]
        runs = {lv: _rollout(lv) for lv in levels}
    finally:
        simd_level(best)
    assert len(levels) >= 1
    first = runs[levels[0]]
    for lv in levels[1:]:
        bad = [k for k, (a, b) in enumerate(zip(first, runs[lv], strict=True)) if a != b]
        assert not bad, f"level {lv} differs from {levels[0]} from step {bad[0]}"
