"""Compiled-map cache: a `RoadMap` saved as an uncompressed, pickle-free .npz (section 2.1).

Parsing a Lanelet2 or OpenDRIVE file and compiling it takes on the order of a second; loading the
compiled arrays back takes milliseconds. Every array of the `RoadMap` dataclasses is stored
under its dotted field path ("lanes.centerlines.points", "grid.cell_offsets" ...), strings as 0-d
unicode arrays, and one JSON string ``__meta__`` holds the format version, the compile
parameters and the sha256 of the source file. Nothing is pickled (`allow_pickle=False`).

Bump `FORMAT_VERSION` whenever a field of `RoadMap` (or of a nested dataclass) changes meaning,
dtype or layout; old caches are then refused with a message telling the user to rebuild.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import hashlib
import json
import os
import tempfile
import time
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from selfplaydrive.errors import MapError
from selfplaydrive.maps.roadmap import RoadMap

__all__ = [
    "FORMAT_VERSION",
    "CacheMeta",
    "file_sha256",
    "load_roadmap",
    "read_meta",
    "remove_stale_temps",
    "save_roadmap",
]

FORMAT_VERSION = 1
_META_KEY = "__meta__"
_FORMAT = "selfplaydrive.roadmap"
# [s] a temporary file this old is a leftover of a killed writer: writing a cache takes well
# under a second, so a live writer's file (another process filling the same cache) is younger
STALE_TMP_AGE = 600.0


@dataclass(frozen=True)
class CacheMeta:
    """What a cache file says about itself.

    Attributes:
        format_version: Layout version of the arrays (`FORMAT_VERSION` when written).
        source_sha256: Hex sha256 of the map file the cache was compiled from ("" if unknown).
        compile_params: Loader and compile keyword arguments used to build the map.
        selfplaydrive_version: Package version that wrote the file.
    """

    format_version: int
    source_sha256: str = ""
    compile_params: dict[str, Any] = field(default_factory=dict)
    selfplaydrive_version: str = ""


def file_sha256(path: str | os.PathLike[str], chunk: int = 1 << 20) -> str:
    """Hex sha256 of a file's bytes.

    Raises:
        MapError: If the file cannot be read.
    """
    h = hashlib.sha256()
    try:
        with open(path, "rb") as f:
            while block := f.read(chunk):
                h.update(block)
    except OSError as exc:
        raise MapError(f"cannot read map file: {exc.strerror or exc}", path) from exc
    return h.hexdigest()


# ---------------------------------------------------------------- flatten / rebuild the dataclasses


@functools.cache
def _field_types(cls: type) -> tuple[tuple[str, Any], ...]:
    # roadmap.py uses `from __future__ import annotations`: resolve the string annotations once
    hints = typing.get_type_hints(cls)
    return tuple((f.name, hints[f.name]) for f in dataclasses.fields(cls))


def _flatten(obj: object, prefix: str, out: dict[str, np.ndarray]) -> None:
    for name, _ in _field_types(type(obj)):
        value = getattr(obj, name)
        key = f"{prefix}{name}"
        if dataclasses.is_dataclass(value):
            _flatten(value, key + ".", out)
        elif isinstance(value, np.ndarray):
            out[key] = value
        else:  # str, float, int, tuple of ints: stored as small arrays
            out[key] = np.asarray(value)


def _expected_keys(cls: type, prefix: str = "") -> list[str]:
    keys: list[str] = []
    for name, tp in _field_types(cls):
        if dataclasses.is_dataclass(tp):
            keys.extend(_expected_keys(tp, f"{prefix}{name}."))
        else:
            keys.append(f"{prefix}{name}")
    return keys


def _scalar(arr: np.ndarray, tp: Any, key: str, path: Path) -> object:
    if arr.ndim != 0 and tp is not np.ndarray and typing.get_origin(tp) is not tuple:
        raise MapError(f"cache entry {key!r} should be a scalar, got shape {arr.shape}", path)
    if tp is str:
        return str(arr[()])
    if tp is float:
        return float(arr[()])
    if tp is int:
        return int(arr[()])
    if typing.get_origin(tp) is tuple:
        return tuple(int(v) for v in arr.reshape(-1))
    return arr


def _rebuild(cls: type, arrays: dict[str, np.ndarray], prefix: str, path: Path) -> Any:
    kwargs = {}
    for name, tp in _field_types(cls):
        key = f"{prefix}{name}"
        if dataclasses.is_dataclass(tp):
            kwargs[name] = _rebuild(tp, arrays, key + ".", path)
        else:
            kwargs[name] = _scalar(arrays[key], tp, key, path)
    return cls(**kwargs)


# ---------------------------------------------------------------- save


def save_roadmap(
    road_map: RoadMap,
    path: str | os.PathLike[str],
    source_sha256: str = "",
    compile_params: dict[str, Any] | None = None,
) -> Path:
    """Write `road_map` to `path` (.npz) atomically: a temporary file, then a rename.

    A crash or a full disk leaves either the old file or no file, never a partial one.

    Args:
        road_map: The compiled map.
        path: Target file; parent folders are created. ".npz" is not appended.
        source_sha256: sha256 of the source map file, for staleness checks.
        compile_params: Loader / compile keyword arguments (JSON-serialisable; others are
            stored as their repr). `max_segment_length` and `cell_size` are always recorded.

    Returns:
        The path written.

    Raises:
        MapError: If the file cannot be written.
    """
    from selfplaydrive import __version__

    path = Path(path)
    remove_stale_temps(path.parent, f".{path.name}.*.tmp")
    params = {"max_segment_length": road_map.max_segment_length, "cell_size": road_map.grid.cell_size}
    params.update(compile_params or {})
    meta = {
        "format": _FORMAT,
        "format_version": FORMAT_VERSION,
        "source_sha256": source_sha256,
        "compile_params": params,
        "selfplaydrive_version": __version__,
    }
    arrays: dict[str, np.ndarray] = {}
    _flatten(road_map, "", arrays)
    arrays[_META_KEY] = np.asarray(json.dumps(meta, sort_keys=True, default=repr))
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:
        raise MapError(f"cannot create cache file: {exc.strerror or exc}", path) from exc
    try:
        with os.fdopen(fd, "wb") as f:
            np.savez(f, **arrays)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(exc, OSError):
            raise MapError(f"cannot write cache file: {exc.strerror or exc}", path) from exc
        raise
    return path


def remove_stale_temps(
    folder: str | os.PathLike[str], pattern: str, max_age: float = STALE_TMP_AGE
) -> list[Path]:
    """Delete the temporary files `save_roadmap` left behind when its process was killed.

    Args:
        folder: Folder to clean (a missing folder is fine).
        pattern: Glob of the temporaries, e.g. ``".town.npz.*.tmp"`` (`save_roadmap` names them
            ``.<target name>.<random>.tmp``).
        max_age: Only files last modified at least this long ago [s] are deleted, so a
            concurrent writer's file survives.

    Returns:
        The files deleted (errors such as a file removed meanwhile are ignored).
    """
    removed = []
    cutoff = time.time() - max_age
    for tmp in Path(folder).glob(pattern):
        with contextlib.suppress(OSError):
            if tmp.is_file() and tmp.stat().st_mtime <= cutoff:
                tmp.unlink()
                removed.append(tmp)
    return removed


# ---------------------------------------------------------------- load


def _parse_meta(raw: np.ndarray | None, path: Path) -> CacheMeta:
    if raw is None:
        raise MapError(
            "not a selfplaydrive map cache (no __meta__ entry): rebuild it with load_map(..., rebuild=True)",
            path,
        )
    try:
        meta = json.loads(str(raw[()]))
        version = int(meta["format_version"])
    except (ValueError, KeyError, TypeError) as exc:
        raise MapError(
            f"cache metadata is corrupted ({exc}): delete the file or pass rebuild=True", path
        ) from exc
    if version != FORMAT_VERSION:
        raise MapError(
            f"cache {path} has format version {version}, this selfplaydrive reads {FORMAT_VERSION}: "
            "delete it or pass rebuild=True",
            path,
        )
    return CacheMeta(
        format_version=version,
        source_sha256=str(meta.get("source_sha256", "")),
        compile_params=dict(meta.get("compile_params", {})),
        selfplaydrive_version=str(meta.get("selfplaydrive_version", "")),
    )


def _read_arrays(path: Path, keys: list[str] | None) -> dict[str, np.ndarray]:
    try:
        with np.load(path, allow_pickle=False) as npz:
            names = npz.files if keys is None else [k for k in keys if k in npz.files]
            return {k: npz[k] for k in names}
    except FileNotFoundError as exc:
        raise MapError("cache file not found", path) from exc
    except Exception as exc:
        # bad zip, bad CRC, truncated member, object arrays (pickle refused), and whatever the
        # npy header parser raises on a damaged header (tokenize.TokenError, SyntaxError ...):
        # every way a file can be unreadable must come out as one MapError the loader handles
        raise MapError(
            f"cache file is corrupted or not a selfplaydrive map cache ({type(exc).__name__}: {exc}): "
            "delete it or pass rebuild=True",
            path,
        ) from exc


def read_meta(path: str | os.PathLike[str]) -> CacheMeta:
    """Read only the metadata of a cache file (cheap: one small zip member).

    Raises:
        MapError: On a missing, corrupted or foreign file, or a format-version mismatch.
    """
    path = Path(path)
    return _parse_meta(_read_arrays(path, [_META_KEY]).get(_META_KEY), path)


def _check_csr(offsets: np.ndarray, count: int, what: str, path: Path) -> None:
    if len(offsets) == 0 or offsets[0] != 0 or offsets[-1] != count or np.any(np.diff(offsets) < 0):
        raise MapError(
            f"cache entry {what} is inconsistent (offsets must rise from 0 to {count}): "
            "delete the file or pass rebuild=True",
            path,
        )


def _check_consistency(m: RoadMap, path: Path) -> None:
    """Cheap structural checks so a damaged but well-formed file fails here, not in a kernel."""
    for name in ("road_edges", "stop_lines", "light_lines", "crosswalks"):
        lines = getattr(m, name)
        _check_csr(lines.offsets, len(lines.points), f"{name}.offsets", path)
    _check_csr(
        m.lanes.centerlines.offsets, len(m.lanes.centerlines.points), "lanes.centerlines.offsets", path
    )
    num_lanes = len(m.lanes)
    if len(m.lanes.centerlines) != num_lanes:
        raise MapError(f"cache has {len(m.lanes.centerlines)} centerlines for {num_lanes} lanes", path)
    _check_csr(m.lanes.succ_offsets, len(m.lanes.succ_index), "lanes.succ_offsets", path)
    _check_csr(m.lanes.pred_offsets, len(m.lanes.pred_index), "lanes.pred_offsets", path)
    nx, ny = m.grid.shape
    if len(m.grid.cell_offsets) != nx * ny + 1:
        raise MapError(f"cache grid has {len(m.grid.cell_offsets)} cell offsets for shape {(nx, ny)}", path)
    _check_csr(m.grid.cell_offsets, len(m.segments), "grid.cell_offsets", path)
    n = len(m.segments)
    for name in ("start", "end", "mid", "dir", "type", "owner"):
        if len(getattr(m.segments, name)) != n:
            raise MapError(f"cache entry segments.{name} has the wrong length (expected {n})", path)


def load_roadmap(
    path: str | os.PathLike[str],
    expect_source_sha: str | None = None,
) -> RoadMap:
    """Load a `RoadMap` written by `save_roadmap`.

    Args:
        path: The .npz file.
        expect_source_sha: If given, the sha256 the cache must have been compiled from.

    Returns:
        The map, with read-only arrays.

    Raises:
        MapError: On a missing or corrupted file, a format-version mismatch, a missing entry
            (cache written by another layout) or a source-sha mismatch (stale cache). The
            message names the file and says to delete it or pass ``rebuild=True``.
    """
    path = Path(path)
    try:
        return _load_checked(path, expect_source_sha)
    except MapError:
        raise
    except Exception as exc:  # a well-formed zip whose entries have the wrong dtype, shape ...
        raise MapError(
            f"cache file is corrupted ({type(exc).__name__}: {exc}): delete it or pass rebuild=True", path
        ) from exc


def _load_checked(path: Path, expect_source_sha: str | None) -> RoadMap:
    arrays = _read_arrays(path, None)
    meta = _parse_meta(arrays.pop(_META_KEY, None), path)
    if expect_source_sha is not None and meta.source_sha256 != expect_source_sha:
        raise MapError(
            f"cache is stale: compiled from source sha256 {meta.source_sha256[:12] or '(unknown)'}..., "
            f"expected {expect_source_sha[:12]}...: delete it or pass rebuild=True",
            path,
        )
    expected = _expected_keys(RoadMap)
    missing = sorted(set(expected) - set(arrays))
    if missing:
        raise MapError(
            f"cache lacks entries {missing[:5]} (written by a different layout): "
            "delete it or pass rebuild=True",
            path,
        )
    road_map = _rebuild(RoadMap, arrays, "", path)
    _check_consistency(road_map, path)
    return road_map
