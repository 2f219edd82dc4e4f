"""Function addresses of compiled components (reward terms, physics models, observation
encoders): one place that checks a numba cfunc's or a Cython capsule's signature against the
ABI (selfplaydrive/include/selfplaydrive_abi.h) before the step calls it through a pointer."""

from __future__ import annotations

import ctypes
from types import ModuleType
from typing import Any

from selfplaydrive.errors import ConfigError

_capsule_get_name = ctypes.pythonapi.PyCapsule_GetName
_capsule_get_name.restype = ctypes.c_char_p
_capsule_get_name.argtypes = [ctypes.py_object]
_capsule_get_pointer = ctypes.pythonapi.PyCapsule_GetPointer
_capsule_get_pointer.restype = ctypes.c_void_p
_capsule_get_pointer.argtypes = [ctypes.py_object, ctypes.c_char_p]


def capsule_name(obj: object) -> str | None:
    """The name of a PyCapsule (Cython names it by the function's C signature); None when
    `obj` is no capsule."""
    if type(obj).__name__ != "PyCapsule":
        return None
    name = _capsule_get_name(obj)
    return name.decode() if name is not None else ""


def normalise(sig: str) -> str:
    """A C signature with uniform spacing, for comparing Cython's capsule names."""
    return " ".join(
        sig.replace("*", " * ").replace(",", " , ").replace("(", " ( ").replace(")", " ) ").split()
    )


def numba_address(what: str, cfunc: Any, signature: Any, hint: str, c_signature: str) -> int:
    """The address of a numba cfunc compiled with `signature`.

    Args:
        what: The component named in errors, e.g. "reward term 'x'".
        cfunc: The ``@numba.cfunc`` object.
        signature: The numba signature the ABI expects.
        hint: Where the user finds it, e.g. "numba_abi.SIGNATURE".
        c_signature: The C signature, for the message.

    Raises:
        ConfigError: Not a cfunc, or compiled with another signature.
    """
    sig = getattr(cfunc, "_sig", None)
    if sig is None or not hasattr(cfunc, "address"):
        raise ConfigError(
            f"{what}: expected a numba cfunc (@numba.cfunc({hint})), got {type(cfunc).__name__}"
        )
    if sig != signature:
        raise ConfigError(
            f"{what}: the cfunc's signature is {sig}, expected {signature} "
            f"({hint}, the C signature {c_signature})"
        )
    return int(cfunc.address)


def cython_capsule(what: str, module: ModuleType, function: str) -> Any:
    """The capsule Cython exports for `function` in ``module.__pyx_capi__``.

    Raises:
        ConfigError: The module does not export `function` (not declared in its .pxd).
    """
    capi = getattr(module, "__pyx_capi__", None) or {}
    if function not in capi:
        raise ConfigError(
            f"{what}: module {module.__name__!r} exports no cdef function {function!r} "
            f"(declare it in the module's .pxd); exported: {sorted(capi)}"
        )
    return capi[function]


def capsule_address(what: str, capsule: Any, want: str, c_name: str) -> int:
    """The function pointer in `capsule`, after checking that its signature is `want` (the
    capsule name Cython gives the library's own function of the same ABI type).

    Raises:
        ConfigError: Not a capsule, or a capsule of another signature.
    """
    got = capsule_name(capsule)
    if got is None:
        raise ConfigError(f"{what}: expected a PyCapsule, got {type(capsule).__name__}")
    if normalise(got) != normalise(want):
        raise ConfigError(f"{what}: the function's signature is {got!r}, expected {want!r} ({c_name})")
    return int(_capsule_get_pointer(capsule, got.encode()))
