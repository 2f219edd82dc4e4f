"""Type stub of the Cython module `selfplaydrive._sim.rules`: the rule reward terms (issues #15, #16)
are cdef only; Python sees their addresses (rewards/rules.py registers them)."""

from typing import Any

__pyx_capi__: dict[str, Any]

def rule_term_addresses() -> dict[str, int]: ...
