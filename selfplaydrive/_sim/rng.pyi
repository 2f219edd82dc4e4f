"""Type stub of the Cython module `selfplaydrive._sim.rng` (only its Python-visible names)."""

import numpy as np
from numpy.typing import NDArray

def uniform(key: int, counter: int, n: int) -> tuple[NDArray[np.float64], int]: ...
def integers(key: int, counter: int, n: int, high: int) -> tuple[NDArray[np.int64], int]: ...
