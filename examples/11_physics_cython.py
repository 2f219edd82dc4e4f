"""Example 11: the unicycle of example 10 as a Cython physics model in its own package.

examples/unicycle_cython/ is a tiny package with its own pyproject.toml: its `.pyx` cimports
the ABI's declarations (`from selfplaydrive_abi cimport Sim, Params`) from the folder
`selfplaydrive.get_include()` and needs nothing else of the library's sources. Declared in its
`.pxd`, the function is exported in the module's `__pyx_capi__` with its C signature, which
`KernelPhysics.from_cython` checks against `sd_physics_fn` before the step calls it (inside
the parallel loop, like the paper's bicycle). Install it once:

    pip install --no-build-isolation examples/unicycle_cython

and select it in one Hydra override: `physics=custom physics.model.target=unicycle_physics:unicycle`.
Without it installed, this script builds it into a temporary folder first (a few seconds).

Run: python examples/11_physics_cython.py [--tiny]
"""

from __future__ import annotations

import atexit
import os
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

from selfplaydrive import make_env
from selfplaydrive.testing.check_physics import check_physics


def import_factory():  # type: ignore[no-untyped-def]
    """`unicycle_physics.unicycle`, building the package first when it is missing."""
    try:
        from unicycle_physics import unicycle
    except ImportError:
        from selfplaydrive.testing.build import build_component_package

        target = Path(tempfile.mkdtemp(prefix="unicycle_physics_"))
        atexit.register(shutil.rmtree, target, ignore_errors=True)
        print(f"building examples/unicycle_cython into {target}")
        build_component_package(Path(__file__).resolve().parent / "unicycle_cython", target)
        sys.path.insert(0, str(target))
        from unicycle_physics import unicycle
    return unicycle


def main(small: bool) -> None:
    model = import_factory()()
    print(model.describe(), f"({model.form})")
    report = check_physics(model, rounds=4 if small else 20)
    print(f"check_physics: passed ({report['agent_steps']} agent-steps)")
    env = make_env("default", num_worlds=2 if small else 16, physics=model, seed=0)
    env.reset(0)
    rng = np.random.default_rng(0)
    steps, dist = (40 if small else 400), 0.0
    for _ in range(steps):
        env.step(np.stack([rng.integers(4, 7, env.num_agents), rng.integers(2, 7, env.num_agents)], axis=1))
        dist += float(env.buffers["speed"][env.masks].sum()) * env.params.dt
    print(f"unicycle (cython): {env.num_agents} agents drove {dist:.1f} m in {steps} steps")


if __name__ == "__main__":
    main("--tiny" in sys.argv or os.environ.get("SELFPLAYDRIVE_EXAMPLE_TINY") == "1")
