"""Build a user's component package (a compiled reward term) against this selfplaydrive.

Used by the tests, the examples and benchmarks/bench_components.py to check the Cython form of
a term end to end: the package is copied to a temporary folder (so nothing of the library's
source tree is visible to it) and installed with pip into `target`, compiled against the
declarations of `selfplaydrive.get_include()` of the selfplaydrive imported here.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path


def build_component_package(src: str | os.PathLike[str], target: str | os.PathLike[str]) -> Path:
    """``pip install --no-build-isolation --no-deps --target target`` of a copy of `src`.

    Args:
        src: Folder of the package (pyproject.toml and setup.py).
        target: Folder to install into; put it on ``sys.path`` to import the package.

    Returns:
        `target` as a Path.

    Raises:
        RuntimeError: The build failed (the message ends with pip's output).
    """
    import selfplaydrive

    target = Path(target)
    # the build's `import selfplaydrive` must find this selfplaydrive (a source tree may come
    # first on sys.path here without being installed)
    root = str(Path(selfplaydrive.__file__).resolve().parents[1])
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([root, *filter(None, [env.get("PYTHONPATH")])])
    with tempfile.TemporaryDirectory() as tmp:
        copy = Path(tmp) / Path(src).name
        shutil.copytree(src, copy, ignore=shutil.ignore_patterns("build", "*.egg-info", "*.so", "*.c"))
        cmd = [sys.executable, "-m", "pip", "install", "--no-build-isolation", "--no-deps", "--no-index",
               "--quiet", "--target", str(target), str(copy)]  # fmt: skip
        done = subprocess.run(cmd, cwd=tmp, env=env, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"building {src} failed ({' '.join(cmd)}):\n{(done.stdout + done.stderr)[-4000:]}")
    return target
