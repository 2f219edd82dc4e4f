"""`load_map`: one entry point for every map source, with the compiled-map cache (section 2.1).

Accepted specs:

- ``"path/to/map.osm"``: Lanelet2 (`selfplaydrive.maps.lanelet2.Lanelet2Loader`);
- ``"path/to/map.xodr"``: OpenDRIVE (`selfplaydrive.maps.opendrive.OpenDriveLoader`);
- ``"path/to/map.npz"``: a compiled-map cache written by `selfplaydrive.maps.cache.save_roadmap`;
- ``"default"``: the bundled procedural town;
- ``"procedural:seed=3,size=800"``: a procedural town (`ProceduralTownLoader`); keys are its
  constructor arguments, values are parsed as int, float, bool or kept as strings.

Source files (.osm, .xodr) go through the cache: the key is the sha256 of the file, the loader
keyword arguments, the cache format version and a fingerprint of the `selfplaydrive.maps` code,
so editing the map, changing an argument or upgrading selfplaydrive rebuilds it automatically.
"""

from __future__ import annotations

import functools
import hashlib
import inspect
import json
import logging
import os
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from selfplaydrive.errors import MapError
from selfplaydrive.maps import cache
from selfplaydrive.maps.base import MapLoader
from selfplaydrive.maps.roadmap import RoadMap

__all__ = [
    "SUPPORTED",
    "cache_path_for",
    "default_cache_dir",
    "load_map",
    "load_maps",
    "parse_procedural_spec",
]

log = logging.getLogger(__name__)

CACHE_ENV_VAR = "SELFPLAYDRIVE_CACHE_DIR"
PROCEDURAL_PREFIX = "procedural"


def _lanelet2(path: Path, **kwargs: Any) -> MapLoader:
    from selfplaydrive.maps.lanelet2 import Lanelet2Loader

    return Lanelet2Loader(path, **kwargs)


def _opendrive(path: Path, **kwargs: Any) -> MapLoader:
    from selfplaydrive.maps.opendrive import OpenDriveLoader

    return OpenDriveLoader(path, **kwargs)


# extension -> (loader module name, part of the cache key; factory). Tests swap entries.
_FILE_LOADERS: dict[str, tuple[str, Callable[..., MapLoader]]] = {
    ".osm": ("selfplaydrive.maps.lanelet2", _lanelet2),
    ".xodr": ("selfplaydrive.maps.opendrive", _opendrive),
}
SUPPORTED = (
    "'.osm' (Lanelet2), '.xodr' (OpenDRIVE), '.npz' (compiled cache), "
    "'default' (bundled procedural town), 'procedural:seed=S,size=M,...'"
)


def default_cache_dir() -> Path:
    """Cache folder: $SELFPLAYDRIVE_CACHE_DIR, else $XDG_CACHE_HOME/selfplaydrive/maps, else
    ~/.cache/selfplaydrive/maps."""
    env = os.environ.get(CACHE_ENV_VAR)
    if env:
        return Path(env).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "selfplaydrive" / "maps"


@functools.cache
def _code_fingerprint() -> str:
    """sha256 over every .py file of `selfplaydrive.maps` (loaders, their helper modules and
    subpackages, the compiler), so code changes invalidate caches built by older code with no
    manual version bump to forget. About a millisecond, once per process."""
    root = Path(__file__).resolve().parent
    h = hashlib.sha256()
    for f in sorted(root.rglob("*.py")):
        h.update(str(f.relative_to(root)).encode())
        h.update(f.read_bytes())
    return h.hexdigest()


def _canonical_kwargs(kwargs: dict[str, Any]) -> str:
    return json.dumps(kwargs, sort_keys=True, default=repr)


def cache_path_for(
    path: str | os.PathLike[str], cache_dir: str | os.PathLike[str] | None = None, **loader_kwargs: Any
) -> Path:
    """Where `load_map(path, cache_dir, **loader_kwargs)` keeps its compiled cache.

    Raises:
        MapError: If the file is missing or its extension is not a source format.
    """
    path = Path(path)
    module, _ = _loader_entry(path)
    return _cache_file(path, cache.file_sha256(path), module, cache_dir, loader_kwargs)


def _cache_file(path: Path, sha: str, module: str, cache_dir: object, kwargs: dict[str, Any]) -> Path:
    key = "\n".join([sha, module, _canonical_kwargs(kwargs), str(cache.FORMAT_VERSION), _code_fingerprint()])
    digest = hashlib.sha256(key.encode()).hexdigest()[:20]
    folder = Path(cache_dir).expanduser() if cache_dir is not None else default_cache_dir()
    return folder / f"{path.stem}.{digest}.npz"


def _loader_entry(path: Path) -> tuple[str, Callable[..., MapLoader]]:
    ext = path.suffix.lower()
    if ext not in _FILE_LOADERS:
        raise MapError(f"unsupported map extension {path.suffix!r}; supported: {SUPPORTED}", path)
    if not path.is_file():
        raise MapError("map file not found", path)
    return _FILE_LOADERS[ext]


def _load_source_file(
    path: Path, cache_dir: object, rebuild: bool, use_cache: bool, kwargs: dict[str, Any]
) -> RoadMap:
    module, factory = _loader_entry(path)
    if not use_cache:
        return factory(path, **kwargs).load()
    sha = cache.file_sha256(path)
    target = _cache_file(path, sha, module, cache_dir, kwargs)
    if target.exists() and not rebuild:
        try:
            road_map = cache.load_roadmap(target, expect_source_sha=sha)
            log.debug("map cache hit: %s", target)
            return road_map
        except Exception as exc:  # stale, damaged, unreadable: the source is still good, rebuild
            log.warning("rebuilding map cache %s from %s: %s", target, path, exc)
    # leftovers of writers killed mid-write (any map's: the folder is ours)
    cache.remove_stale_temps(target.parent, ".*.npz.*.tmp")
    road_map = factory(path, **kwargs).load()
    try:
        cache.save_roadmap(road_map, target, source_sha256=sha, compile_params=kwargs)
    except MapError as exc:  # a read-only cache folder must not stop training
        warnings.warn(
            f"could not write the map cache ({exc}); the map is compiled again next time", stacklevel=3
        )
    return road_map


def _parse_value(text: str) -> object:
    low = text.lower()
    if low in ("true", "false"):
        return low == "true"
    for conv in (int, float):
        try:
            return conv(text)
        except ValueError:
            pass
    return text


def parse_procedural_spec(spec: str) -> dict[str, Any]:
    """``"procedural:seed=3,size=800"`` -> ``{"seed": 3, "size": 800}``.

    Raises:
        MapError: On an item that is not ``key=value`` or a repeated key.
    """
    _, _, rest = spec.partition(":")
    params: dict[str, Any] = {}
    for item in filter(None, (s.strip() for s in rest.split(","))):
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or not key.isidentifier():
            raise MapError(
                f"procedural map spec item {item!r} is not key=value; example: 'procedural:seed=3,size=800'",
                spec,
            )
        if key in params:
            raise MapError(f"procedural map spec repeats key {key!r}", spec)
        params[key] = _parse_value(value.strip())
    return params


def _call_checked(fn: Callable[..., Any], what: str, spec: str, kwargs: dict[str, Any]) -> Any:
    try:
        inspect.signature(fn).bind(**kwargs)
    except TypeError as exc:
        params = ", ".join(inspect.signature(fn).parameters)
        raise MapError(f"bad arguments for {what} ({exc}); accepted: {params}", spec) from exc
    return fn(**kwargs)


def _load_procedural(spec: str, kwargs: dict[str, Any]) -> RoadMap:
    from selfplaydrive.maps.procedural import ProceduralTownLoader

    params = {**parse_procedural_spec(spec), **kwargs}
    return _call_checked(ProceduralTownLoader, "ProceduralTownLoader", spec, params).load()


def _load_default(kwargs: dict[str, Any]) -> RoadMap:
    from selfplaydrive.maps.procedural import load_default_map

    return _call_checked(load_default_map, "load_default_map", "default", kwargs)


def load_map(
    spec: str | os.PathLike[str] | RoadMap,
    cache_dir: str | os.PathLike[str] | None = None,
    rebuild: bool = False,
    use_cache: bool = True,
    **loader_kwargs: Any,
) -> RoadMap:
    """Load a map from a file, the bundled default or a procedural spec (see module docstring).

    Args:
        spec: Path (.osm, .xodr, .npz), ``"default"``, ``"procedural:key=value,..."``, or an
            already compiled `RoadMap` (returned as is).
        cache_dir: Folder of compiled caches; default `default_cache_dir()`.
        rebuild: Recompile and overwrite the cache even if a valid one exists.
        use_cache: False compiles from source without reading or writing the cache.
        **loader_kwargs: Passed to the loader's constructor (projection, compile parameters
            such as ``max_segment_length`` [m] ...); part of the cache key.

    Returns:
        The compiled map.

    Raises:
        MapError: On an unknown extension (the message lists the supported ones), a missing
            file, a malformed map, or a cache that cannot be read (for .npz specs).
    """
    if isinstance(spec, RoadMap):
        return spec
    text = os.fspath(spec)
    if text == "default":
        return _load_default(loader_kwargs)
    if text == PROCEDURAL_PREFIX or text.startswith(PROCEDURAL_PREFIX + ":"):
        return _load_procedural(text, loader_kwargs)
    path = Path(text).expanduser()
    if path.suffix.lower() == ".npz":
        if loader_kwargs:
            raise MapError(
                f"a compiled .npz map takes no loader arguments, got {sorted(loader_kwargs)}", path
            )
        return cache.load_roadmap(path)
    return _load_source_file(path, cache_dir, rebuild, use_cache, loader_kwargs)


def load_maps(specs: Sequence[str | os.PathLike[str] | RoadMap], **kwargs: Any) -> list[RoadMap]:
    """Several maps for one env (`map=several`): every world draws one of them, uniformly, at
    each reset (`VecEnv`), e.g. the bundled town beside procedural towns of other lane widths.

    Args:
        specs: One `load_map` spec per map (paths, ``"default"``, ``"procedural:key=value,..."``).
        **kwargs: Passed to every `load_map` call (cache_dir, loader arguments).

    Raises:
        MapError: `specs` is a single string or empty (the message shows what was given), or a
            map fails to load (`load_map`'s error, which names the spec).
    """
    if isinstance(specs, (str, os.PathLike, RoadMap)) or not len(specs):
        raise MapError(
            f"map.specs: expected a non-empty list of map specs such as [default, 'procedural:seed=3'], "
            f"got {specs!r}"
        )
    return [load_map(spec, **kwargs) for spec in specs]
