"""Example 07: the speed-limit term of example 06 as a numba cfunc (needs the `numba` extra).

The cfunc has the C signature of every reward component (`sd_reward_term_fn` in
selfplaydrive_abi.h; `numba_abi.SIGNATURE`), so the step calls it through a function pointer
once per world inside its parallel loop, without the GIL, like the paper's own terms: no build
step, no Python per step. It reads the state through the field offsets of the header
(`SIM.speed`, ...) and writes only its column, `out[a * stride]` for slot a of world w. Its
parameters travel in `args` (float32: coef, limit).

Run: python examples/07_term_numba.py [--tiny]   (pip install 'selfplaydrive[numba]')
"""

from __future__ import annotations

import sys

import numpy as np
from _terms import drive, tiny
from numba import cfunc

from selfplaydrive.rewards import KernelTerm
from selfplaydrive.rewards.numba_abi import SIGNATURE, SIM, f32_ptr, int_field, u8_ptr


@cfunc(SIGNATURE)
def speed_limit(sim, prm, atlas, args, w, out, stride):  # type: ignore[no-untyped-def]
    """R = -args[0] * max(v - args[1], 0) for every active slot of world w."""
    A = int_field(sim, SIM.A)
    speed = f32_ptr(sim, SIM.speed)
    active = u8_ptr(sim, SIM.active)
    for a in range(A):
        i = w * A + a
        if active[i]:
            out[a * stride] = -args[0] * max(speed[i] - args[1], np.float32(0.0))


def speed_limit_term(coef: float = 0.01, limit: float = 14.0) -> KernelTerm:
    """The cfunc as a term; `from_numba` checks its signature."""
    return KernelTerm.from_numba("speed_limit", speed_limit, args=(coef, limit))


if __name__ == "__main__":
    drive(speed_limit_term(), small=tiny(sys.argv))
