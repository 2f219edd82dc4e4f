"""An observation encoder named by a target string: `obs=custom obs.target=...` selects an
encoder defined outside the package in one Hydra override (docs/components.md "Write an
observation encoder"), as `physics=custom` does for physics models."""

from __future__ import annotations

from typing import Any

from selfplaydrive._targets import load_attr
from selfplaydrive.errors import ConfigError
from selfplaydrive.obs.encoders import Encoder, KernelEncoder, as_encoder


def load_encoder(target: str, **kwargs: Any) -> Encoder:
    """The encoder named by `target`: ``"package.module:attr"`` or ``"path/to/file.py:attr"``;
    `attr` is an encoder (a `KernelEncoder` or a Python encoder) or a factory of one called
    with `kwargs` (``obs=custom obs.target=examples/09_encoder_numba.py:ego_objects_encoder
    +obs.max_objects=8``).

    Raises:
        ConfigError: A malformed target, a module or attribute that does not exist, keys given
            to an encoder that is not a factory, or an object that is not an encoder.
    """
    obj = load_attr(target, "obs.target", "encoder")
    enc = obj if _is_encoder(obj) else obj(**kwargs) if callable(obj) else obj
    if kwargs and enc is obj:
        raise ConfigError(f"obs.target {target!r}: an encoder, not a factory; it takes no {sorted(kwargs)}")
    if not _is_encoder(enc):
        raise ConfigError(
            f"obs.target {target!r}: expected an observation encoder (a KernelEncoder, or name, layout, "
            f"radius and __call__(state)) or a factory of one, got {type(enc).__name__}"
        )
    return as_encoder(enc)


def _is_encoder(obj: object) -> bool:
    if isinstance(obj, type):
        return False
    return isinstance(obj, KernelEncoder) or (callable(obj) and hasattr(obj, "layout"))
