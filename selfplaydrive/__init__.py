"""selfplaydrive: composable, fast self-play driving environments (Sisask, Tampuu, Matiisen).

The simulator core imports no torch; trainers and models do. Importing the package registers
the gymnasium ids ``selfplaydrive/SingleAgent-v0`` and ``selfplaydrive/SelfPlay-v0``
(`selfplaydrive.env.registration`; string entry points, so nothing heavy is imported).
"""

__version__ = "0.1.0"

import os

from selfplaydrive.builder import make_env
from selfplaydrive.env.registration import register_envs

register_envs()


def get_include() -> str:
    """Folder of the component ABI's declarations (selfplaydrive_abi.h for C,
    selfplaydrive_abi.pxd for Cython), like `numpy.get_include()`: put it on the include path
    of an extension that implements a component (docs/components.md)."""
    return os.path.join(os.path.dirname(os.path.abspath(__file__)), "include")


__all__ = ["__version__", "get_include", "make_env"]
