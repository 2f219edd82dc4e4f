"""Type stub of the Cython module `selfplaydrive._sim.shaping`: the shaping reward terms of
issue #16 are cdef only; Python sees their addresses (rewards/shaping.py registers them)."""

from typing import Any

__pyx_capi__: dict[str, Any]

def shaping_term_addresses() -> dict[str, int]: ...
