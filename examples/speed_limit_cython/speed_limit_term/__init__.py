"""A selfplaydrive reward term written in Cython (examples/08_term_cython.py uses it).

R = -coef * max(v - limit, 0) per step, v the speed [m/s]: the same term as the NumPy form
(examples/06_term_python.py) and the numba form (examples/07_term_numba.py).
"""

from __future__ import annotations

from selfplaydrive.rewards import KernelTerm
from speed_limit_term import _kernel


def speed_limit_term(coef: float = 0.01, limit: float = 14.0, name: str = "speed_limit") -> KernelTerm:
    """The term as a `KernelTerm`, ready for `LinearReward(..., terms=[...])`.

    Args:
        coef: Penalty per m/s above the limit per step.
        limit: Speed limit [m/s].
        name: Column name.
    """
    return KernelTerm.from_cython(name, _kernel, "speed_limit", args=(coef, limit))
