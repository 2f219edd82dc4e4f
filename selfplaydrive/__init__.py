"""selfplaydrive: composable, fast self-play driving environments (Sisask, Tampuu, Matiisen).

The simulator core imports no torch; trainers and models do.
"""

__version__ = "0.1.0"

from selfplaydrive.builder import make_env

__all__ = ["__version__", "make_env"]
