"""Example 06: a reward term in Python/NumPy (the first of three forms of one term, 06-08).

The term penalises speeding: R = -coef * max(v - limit, 0) per 0.1 s step, v the speed [m/s]
(paper section 2.3 has no such term; section 6 asks for more traffic-rule terms). Written in
NumPy it runs after the compiled step on read-only views of the state (`env.state`), gets its
own column in `env.reward_terms` (named in `env.term_names`), its own episode sum and the
trainer's `term/speed_limit` tag. A Python term named like a registered one (e.g. "collision")
replaces it in that env.

The same term compiled: 07 (numba cfunc, no build step) and 08 (a Cython package); they give
the same values to float32 rounding and run inside the parallel step (docs/components.md).

Run: python examples/06_term_python.py [--tiny]
"""

from __future__ import annotations

import sys

import numpy as np
from _terms import drive, tiny


class SpeedLimit:
    """R = -coef * max(v - limit, 0).

    Args:
        coef: Penalty per m/s above the limit per step.
        limit: Speed limit [m/s] (14 m/s is about 50 km/h).
    """

    name = "speed_limit"

    def __init__(self, coef: float = 0.01, limit: float = 14.0) -> None:
        self.coef = np.float32(coef)
        self.limit = np.float32(limit)

    def __call__(self, state: object) -> np.ndarray:
        """(N,) float32 from the (N,) speeds; rows of slots without an agent are ignored."""
        over = np.maximum(state.speed - self.limit, np.float32(0.0))
        return -self.coef * over


if __name__ == "__main__":
    drive(SpeedLimit(), small=tiny(sys.argv))
