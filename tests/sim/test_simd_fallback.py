"""The SSE2 row writers and scan of _sim/rows.h and _sim/scan.h against their plain-C
fallbacks (used where SSE2 is missing, e.g. ARM): bit-identical results."""

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
    inner, shell = out.stdout.split("inner ")[1].split(" shell ")
    a, b = inner.split("/")
    c, d = shell.split("/")
    assert a == b and c == d.strip() and int(a) > 0 and int(c) > 0  # scan counts match a direct count
