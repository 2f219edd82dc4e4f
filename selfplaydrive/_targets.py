"""Objects named by a target string, for the Hydra options that select a component defined
outside the package in one override (`physics=custom physics.model.target=...`,
`obs=custom obs.target=...`; docs/components.md).

A target is ``"package.module:attr"`` or ``"path/to/file.py:attr"``; a file is imported once per
process under a private module name, with its own folder on the path while it runs (so it may
import its neighbours).
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
from pathlib import Path
from types import ModuleType

from selfplaydrive.errors import ConfigError


def load_attr(target: object, key: str, kind: str) -> object:
    """The attribute `target` names.

    Args:
        target: ``"module:attr"`` or ``"file.py:attr"``.
        key: The config key that holds it (named by every error), e.g. "obs.target".
        kind: Word for the private module names of imported files ("physics", "encoder").

    Raises:
        ConfigError: A malformed target, a file or module that does not exist or fails to
            import, or a module without the attribute (the message lists its public names).
    """
    if not isinstance(target, str) or ":" not in target:
        raise ConfigError(f"{key}: expected 'module:attr' or 'file.py:attr', got {target!r}")
    where, attr = target.rsplit(":", 1)
    module = _import(where, target, key, kind)
    if not hasattr(module, attr):
        public = sorted(n for n in vars(module) if not n.startswith("_"))
        raise ConfigError(f"{key} {target!r}: {where!r} has no {attr!r}; it has {public}")
    return getattr(module, attr)


def _import(where: str, target: str, key: str, kind: str) -> ModuleType:
    if where.endswith(".py"):
        return _import_file(Path(where).expanduser().resolve(), target, key, kind)
    try:
        return importlib.import_module(where)
    except ImportError as exc:
        raise ConfigError(f"{key} {target!r}: cannot import {where!r}: {exc}") from exc


def _import_file(path: Path, target: str, key: str, kind: str) -> ModuleType:
    if not path.is_file():
        raise ConfigError(f"{key} {target!r}: no file {str(path)!r}")
    name = f"_selfplaydrive_{kind}_{path.stem}_{abs(hash(str(path)))}"
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.path.insert(0, str(path.parent))  # the file's own imports of its neighbours
    try:
        sys.modules[name] = module
        spec.loader.exec_module(module)
    except Exception:
        sys.modules.pop(name, None)
        raise
    finally:
        sys.path.remove(str(path.parent))
    return module
