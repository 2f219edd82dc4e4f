"""Example 08: the speed-limit term of example 06 in Cython, as its own package.

examples/speed_limit_cython/ is a tiny package with its own pyproject.toml: its `.pyx`
cimports the ABI's declarations (`from selfplaydrive_abi cimport Sim, ...`) from the folder
`selfplaydrive.get_include()` and needs nothing else of the library's sources. Declared in its
`.pxd`, the function is exported in the module's `__pyx_capi__` with its C signature, which
`KernelTerm.from_cython` checks before the step calls it (inside the parallel loop, like the
paper's terms). Install it once:

    pip install --no-build-isolation examples/speed_limit_cython

Without it installed, this script builds it into a temporary folder first (a few seconds).

Run: python examples/08_term_cython.py [--tiny]
"""

from __future__ import annotations

import atexit
import shutil
import sys
import tempfile
from pathlib import Path

from _terms import drive, tiny


def import_term():  # type: ignore[no-untyped-def]
    """`speed_limit_term.speed_limit_term`, building the package first when it is missing."""
    try:
        from speed_limit_term import speed_limit_term
    except ImportError:
        from selfplaydrive.testing.build import build_component_package

        target = Path(tempfile.mkdtemp(prefix="speed_limit_term_"))
        atexit.register(shutil.rmtree, target, ignore_errors=True)
        print(f"building examples/speed_limit_cython into {target}")
        build_component_package(Path(__file__).resolve().parent / "speed_limit_cython", target)
        sys.path.insert(0, str(target))
        from speed_limit_term import speed_limit_term
    return speed_limit_term


if __name__ == "__main__":
    drive(import_term()(), small=tiny(sys.argv))
