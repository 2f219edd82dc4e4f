"""NumPy reference of the shaping terms (issue #16; kernels in selfplaydrive/_sim/shaping.pyx).

Plain loops in float32 with the kernel's order of operations (tests/rewards/test_shaping.py
compares them on random rollouts). Takes the env state after a step (`VecEnv.state`) and the
term's parameters; returns the (N,) values of the active slots (0 elsewhere).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

F = np.float32


def approach(px: F, py: F, vx: F, vy: F, horizon: F, reach: F) -> F:
    """1 - t / horizon at a closest approach nearer than `reach` within the horizon, else 0."""
    vv = F(vx * vx + vy * vy)
    t = F(0.0)
    if vv > F(1e-6):
        t = F(-(px * vx + py * vy) / vv)
        t = min(max(t, F(0.0)), horizon)
    dx, dy = F(px + vx * t), F(py + vy * t)
    return F(F(1.0) - t / horizon) if F(dx * dx + dy * dy) < F(reach * reach) else F(0.0)


def conflict(st: Any, params: Sequence[float]) -> np.ndarray:
    """Values of `conflict` (-max over bodies of `approach`) for every slot."""
    W = len(st.map_id)
    A, S, P = len(st.x) // W, len(st.st_x) // W, len(st.ped_x) // W
    horizon, margin = F(params[0]), F(params[1])
    out = np.zeros(W * A, F)
    for w in range(W):
        for a in range(A):
            i = w * A + a
            if not st.active[i]:
                continue
            xa, ya = F(st.x[i]), F(st.y[i])
            vxa, vya = F(st.speed[i] * st.hcos[i]), F(st.speed[i] * st.hsin[i])
            hwa = F(F(0.5) * st.width[i] + margin)
            worst = F(0.0)
            for b in range(A):
                j = w * A + b
                if b == a or not (st.active[j] or st.obstacle[j]):
                    continue
                vxb = F(st.speed[j] * st.hcos[j]) if st.active[j] else F(0.0)
                vyb = F(st.speed[j] * st.hsin[j]) if st.active[j] else F(0.0)
                reach = F(hwa + F(0.5) * st.width[j])
                c = approach(F(st.x[j] - xa), F(st.y[j] - ya), F(vxb - vxa), F(vyb - vya), horizon, reach)
                worst = max(worst, c)
            for b in range(S):
                j = w * S + b
                if st.st_valid[j]:
                    reach = F(hwa + F(0.5) * st.st_wid[j])
                    c = approach(F(st.st_x[j] - xa), F(st.st_y[j] - ya), -vxa, -vya, horizon, reach)
                    worst = max(worst, c)
            for b in range(P):
                j = w * P + b
                if st.ped_valid[j] and st.ped_here[j]:
                    reach = F(hwa + F(0.5) * st.ped_wid[j])
                    dvx, dvy = F(st.ped_vx[j] - vxa), F(st.ped_vy[j] - vya)
                    c = approach(F(st.ped_x[j] - xa), F(st.ped_y[j] - ya), dvx, dvy, horizon, reach)
                    worst = max(worst, c)
            out[i] = -worst
    return out
