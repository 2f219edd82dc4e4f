"""Type stub of the Cython module `selfplaydrive._sim.spatial` (only its Python-visible names)."""

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

def query_radius_batch(
    road_map: Any, points: ArrayLike, radius: float, cap: int = 4096
) -> tuple[NDArray[np.int32], NDArray[np.int32]]: ...
