"""Load a Python file that is not part of an importable package as a module: tests/sim/helpers.py
(tests/ is not a package), the benchmarks/ scripts and the examples/ files (whose names start
with digits)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parents[1]


def load_file(path: Path | str, name: str, *, register: bool = False) -> ModuleType:
    """Import the file at `path` as a module called `name`.

    Args:
        path: The .py file.
        name: The module's name.
        register: Keep the module in `sys.modules` under `name`, for a Hydra `_target_` that
            names it.

    Returns:
        The executed module. Its folder is on `sys.path` while it runs, so an example can import
        its siblings (examples/07_term_numba.py imports `_terms`).
    """
    path = Path(path)
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise ImportError(f"{path}: not a Python file that can be loaded as module {name!r}")
    module = importlib.util.module_from_spec(spec)
    if register:
        sys.modules[name] = module
    sys.path.insert(0, str(path.parent))
    try:
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(str(path.parent))
    return module


def load_sim_helpers() -> ModuleType:
    """tests/sim/helpers.py (make_scenario and friends) as the module `sim_helpers`."""
    return load_file(ROOT / "tests" / "sim" / "helpers.py", "sim_helpers")
