"""The component ABI for numba (optional extra ``numba``): write a reward term as a ``cfunc``.

The struct types are read from selfplaydrive_abi.h itself (the header the kernels compile
against), so the numba view cannot drift from the C one. `SIM`, `PARAMS`, `ATLAS` give the
byte offset of every field; `int_field` / `float_field` read a scalar field and `f32_ptr`,
`u8_ptr`, ... a pointer field as a typed pointer. A term:

    from numba import cfunc
    from selfplaydrive.rewards.numba_abi import SIGNATURE, SIM, f32_ptr, int_field, u8_ptr

    @cfunc(SIGNATURE)
    def speed_limit(sim, prm, atlas, args, w, out, stride):
        A = int_field(sim, SIM.A)
        speed, active = f32_ptr(sim, SIM.speed), u8_ptr(sim, SIM.active)
        for a in range(A):
            i = w * A + a
            if active[i]:
                out[a * stride] = -args[0] * max(speed[i] - args[1], np.float32(0.0))

    term = KernelTerm.from_numba("speed_limit", speed_limit, args=(0.1, 14.0))

Arguments as in `sd_reward_term_fn`: `sim`, `prm`, `atlas` are the structs' addresses (void
pointers, read through the offsets), `args` the term's float32 parameters, `w` the world, `out` the column
(write ``out[a * stride]`` for slot a), `stride` the row width of the per-term buffer.
"""

from __future__ import annotations

import os
import re
from collections import namedtuple
from typing import Any

import numpy as np

from selfplaydrive._optional import requires_extra

with requires_extra("numba"):
    import numba
    from numba import types
    from numba.extending import intrinsic

_C_TYPES = {
    "int": np.int32,
    "float": np.float32,
    "double": np.float64,
    "int8_t": np.int8,
    "uint8_t": np.uint8,
    "int32_t": np.int32,
    "int64_t": np.int64,
    "uint64_t": np.uint64,
}


def header_path() -> str:
    """Path of selfplaydrive_abi.h."""
    from selfplaydrive import get_include

    return os.path.join(get_include(), "selfplaydrive_abi.h")


def struct_fields(struct: str, header: str | None = None) -> list[tuple[str, str]]:
    """(field name, C type) of `typedef struct sd_<struct>` in the header, in declaration order."""
    with open(header or header_path()) as f:
        text = re.sub(r"/\*.*?\*/", "", f.read(), flags=re.S)
    m = re.search(rf"typedef struct sd_{struct} \{{(.*?)\}} sd_{struct};", text, flags=re.S)
    if m is None:
        raise LookupError(f"selfplaydrive_abi.h declares no struct sd_{struct}")
    fields = []
    for decl in m.group(1).split(";"):
        decl = " ".join(decl.split())
        if decl:
            ctype, name = decl.rsplit(" ", 1)
            fields.append((name, ctype))
    return fields


def struct_dtype(struct: str) -> np.dtype:
    """NumPy dtype with the C layout of `sd_<struct>`: pointers are uintp addresses."""
    spec = []
    for name, ctype in struct_fields(struct):
        base = ctype.replace("const ", "").strip()
        spec.append((name, np.uintp if base.endswith("*") else _C_TYPES[base]))
    return np.dtype(spec, align=True)


def _offsets(struct: str) -> Any:
    """Byte offset of every field of `sd_<struct>`, as a namedtuple (numba freezes it as a
    constant inside jitted code)."""
    dt = struct_dtype(struct)
    names = list(dt.names or ())
    return namedtuple(f"sd_{struct}_offsets", names)(*(int(dt.fields[n][1]) for n in names))


SIM = _offsets("sim")
PARAMS = _offsets("params")
ATLAS = _offsets("atlas")
# sd_reward_term_fn as a numba signature: the structs arrive as void pointers and are read
# through the offsets above (numba cannot lower attribute access through record pointers)
SIGNATURE = types.void(
    types.voidptr,
    types.voidptr,
    types.voidptr,
    types.CPointer(types.float32),
    types.int32,
    types.CPointer(types.float32),
    types.int32,
)

# sd_encoder_fn (observation encoders, docs/components.md "Write an observation encoder"): the
# same numba types, `args` (the C `const void*`) seen as float32 parameters and `out` the
# world's first observation row (row a at out[a * stride])
ENCODER_SIGNATURE = SIGNATURE


@intrinsic
def _load(typingctx, base, offset, dtype):  # type: ignore[no-untyped-def]
    """The value of type `dtype` at byte `offset` of the struct at `base`."""
    value_type = dtype.dtype

    def codegen(context, builder, signature, args):  # type: ignore[no-untyped-def]
        at = builder.gep(args[0], [args[1]])
        ptr = builder.bitcast(at, context.get_value_type(value_type).as_pointer())
        return builder.load(ptr)

    return value_type(base, offset, dtype), codegen


@intrinsic
def _pointer(typingctx, address, dtype):  # type: ignore[no-untyped-def]
    """Typed pointer from an integer address."""
    ptr_type = types.CPointer(dtype.dtype)

    def codegen(context, builder, signature, args):  # type: ignore[no-untyped-def]
        return builder.inttoptr(args[0], context.get_value_type(ptr_type))

    return ptr_type(address, dtype), codegen


@numba.njit(inline="always")
def int_field(base, offset):  # type: ignore[no-untyped-def]
    """An `int` field: ``int_field(sim, SIM.A)``."""
    return _load(base, offset, numba.int32)


@numba.njit(inline="always")
def float_field(base, offset):  # type: ignore[no-untyped-def]
    """A `float` field: ``float_field(prm, PARAMS.dt)``."""
    return _load(base, offset, numba.float32)


@numba.njit(inline="always")
def f32_ptr(base, offset):  # type: ignore[no-untyped-def]
    """A `float*` field as a pointer to index: ``f32_ptr(sim, SIM.speed)[i]``."""
    return _pointer(_load(base, offset, numba.uintp), numba.float32)


@numba.njit(inline="always")
def f64_ptr(base, offset):  # type: ignore[no-untyped-def]
    """A `double*` field."""
    return _pointer(_load(base, offset, numba.uintp), numba.float64)


@numba.njit(inline="always")
def i32_ptr(base, offset):  # type: ignore[no-untyped-def]
    """An `int32_t*` field."""
    return _pointer(_load(base, offset, numba.uintp), numba.int32)


@numba.njit(inline="always")
def i64_ptr(base, offset):  # type: ignore[no-untyped-def]
    """An `int64_t*` field."""
    return _pointer(_load(base, offset, numba.uintp), numba.int64)


@numba.njit(inline="always")
def u8_ptr(base, offset):  # type: ignore[no-untyped-def]
    """A `uint8_t*` field (flags, event bits)."""
    return _pointer(_load(base, offset, numba.uintp), numba.uint8)


@numba.njit(inline="always")
def i8_ptr(base, offset):  # type: ignore[no-untyped-def]
    """An `int8_t*` field (light states)."""
    return _pointer(_load(base, offset, numba.uintp), numba.int8)
