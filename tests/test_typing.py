"""Static typing: mypy passes on the typed public modules (`[tool.mypy]` of pyproject.toml), the
Cython modules have stubs that match the compiled code, and type checkers can see them."""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

pytest.importorskip("mypy", reason="mypy is not installed (pip install 'selfplaydrive[dev]')")

ROOT = Path(__file__).resolve().parents[1]
SIM = ROOT / "selfplaydrive" / "_sim"
# outside the repository (no .mypy_cache in the working tree) and kept between runs (warm: ~2 s)
CACHE = str(Path(tempfile.gettempdir()) / "selfplaydrive-mypy-cache")
# Cython's own additions to every compiled module, not part of the package's interface
STUBTEST_ALLOWLIST = r"""
selfplaydrive\._sim\.\w+\.__pyx_capi__
selfplaydrive\._sim\.\w+\.__test__
selfplaydrive\._sim\.\w+(\.\w+)?\.__reduce_cython__
selfplaydrive\._sim\.\w+(\.\w+)?\.__setstate_cython__
"""


def _run(*args: str, timeout: float = 600) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, *args], cwd=ROOT, capture_output=True, text=True, timeout=timeout, check=False
    )


def test_mypy_passes_on_the_typed_modules():
    r = _run("-m", "mypy", "--cache-dir", CACHE)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "Success: no issues found in" in r.stdout
    assert int(r.stdout.split("found in ")[1].split()[0]) >= 12  # the configured files were checked


def test_mypy_sees_the_cython_stubs(tmp_path):
    # without the stubs the kernels are untyped (Any) and this call would pass unnoticed
    bad = tmp_path / "bad_call.py"
    bad.write_text("from selfplaydrive._sim.world import copy_discrete\n\ncopy_discrete('actions')\n")
    r = _run("-m", "mypy", "--cache-dir", CACHE, "--config-file", "pyproject.toml", str(bad))
    assert r.returncode == 1, r.stdout + r.stderr
    assert 'Missing positional arguments "out", "n_acc", "n_steer"' in r.stdout


def test_every_cython_module_has_a_stub():
    assert sorted(p.stem for p in SIM.glob("*.pyx")) == sorted(p.stem for p in SIM.glob("*.pyi"))
    assert (ROOT / "selfplaydrive" / "py.typed").is_file()
    package_data = next(
        line for line in (ROOT / "pyproject.toml").read_text().splitlines() if line.startswith('"*" = [')
    )
    assert '"*.pyi"' in package_data and '"py.typed"' in package_data  # shipped in the wheel


def test_stubs_match_the_compiled_modules(tmp_path):
    allowlist = tmp_path / "allowlist.txt"
    allowlist.write_text(STUBTEST_ALLOWLIST)
    modules = [f"selfplaydrive._sim.{p.stem}" for p in sorted(SIM.glob("*.pyx"))]
    r = _run(
        "-m",
        "mypy.stubtest",
        "--mypy-config-file",
        "pyproject.toml",
        "--ignore-disjoint-bases",  # Cython extension types; nothing subclasses them
        "--allowlist",
        str(allowlist),
        *modules,
    )
    assert r.returncode == 0, r.stdout + r.stderr
