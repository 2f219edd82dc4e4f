"""Type stub of the Cython module `selfplaydrive._sim.physics` (the kernels are cdef only)."""

from typing import Any

BICYCLE_ARGS: tuple[str, ...]
JERK_ARGS: tuple[str, ...]
DELTA_ARGS: tuple[str, ...]
JERK_STATE: tuple[str, ...]
__pyx_capi__: dict[str, Any]

def model_addresses() -> dict[str, int]: ...
