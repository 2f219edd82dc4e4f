"""The physics-model ABI for numba (optional extra ``numba``): write a model as a ``cfunc``.

The field offsets and typed-pointer helpers are those of the reward terms
(selfplaydrive/rewards/numba_abi.py, read from selfplaydrive_abi.h itself); `SIGNATURE` is
`sd_physics_fn`. A model that moves every active car straight on at its speed:

    from numba import cfunc
    from selfplaydrive.physics.numba_abi import SIGNATURE, SIM, PARAMS, f32_ptr, float_field, int_field

    @cfunc(SIGNATURE)
    def coast(sim, prm, args, w, state):
        A, dt = int_field(sim, SIM.A), float_field(prm, PARAMS.dt)
        x, hcos, speed, active = f32_ptr(sim, SIM.x), f32_ptr(sim, SIM.hcos), ...
        for a in range(A):
            i = w * A + a
            if active[i]:
                x[i] += speed[i] * hcos[i] * dt   # ... y likewise; heading unchanged

    model = KernelPhysics.from_numba("coast", coast)

Arguments as in `sd_physics_fn`: `sim`, `prm` are the structs' addresses (void pointers, read
through the offsets), `args` the model's float32 parameters, `w` the world, `state` the world's
(A, state_dim) rows of the model's own state (float32, zero at spawn).
"""

from __future__ import annotations

from selfplaydrive._optional import requires_extra
from selfplaydrive.rewards.numba_abi import (
    ATLAS,
    PARAMS,
    SIM,
    f32_ptr,
    f64_ptr,
    float_field,
    i8_ptr,
    i32_ptr,
    i64_ptr,
    int_field,
    u8_ptr,
)

with requires_extra("numba"):
    from numba import types

# sd_physics_fn as a numba signature (the structs arrive as void pointers)
SIGNATURE = types.void(
    types.voidptr,
    types.voidptr,
    types.CPointer(types.float32),
    types.int32,
    types.CPointer(types.float32),
)

__all__ = [
    "ATLAS",
    "PARAMS",
    "SIGNATURE",
    "SIM",
    "f32_ptr",
    "f64_ptr",
    "float_field",
    "i8_ptr",
    "i32_ptr",
    "i64_ptr",
    "int_field",
    "u8_ptr",
]
