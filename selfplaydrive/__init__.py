"""selfplaydrive: composable, fast self-play driving environments (Sisask, Tampuu, Matiisen).

The simulator core imports no torch; trainers and models do. Importing the package registers
the gymnasium ids ``selfplaydrive/SingleAgent-v0`` and ``selfplaydrive/SelfPlay-v0``
(`selfplaydrive.env.registration`; string entry points, so nothing heavy is imported).
"""

__version__ = "0.1.0"

from selfplaydrive.builder import make_env
from selfplaydrive.env.registration import register_envs

register_envs()

__all__ = ["__version__", "make_env"]
