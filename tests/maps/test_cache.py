"""Compiled-map cache: exact round trip, refusal of stale / damaged files, atomic writes."""

from __future__ import annotations

import dataclasses
import json
import os
import time
import zipfile

import numpy as np
import pytest

from selfplaydrive.errors import MapError
from selfplaydrive.maps import (
    CrosswalkElement,
    LaneElement,
    LaneKind,
    MapElements,
    PolylineElement,
    StopKind,
    StopLineElement,
    TrafficLightElement,
    cache,
    compile_map,
)
from selfplaydrive.maps.cache import FORMAT_VERSION, load_roadmap, read_meta, save_roadmap


@pytest.fixture
def junction_map():
    """A lane into a junction with every element type, so every array is non-empty."""
    lanes = [
        LaneElement(np.array([[0.0, 0.0], [100.0, 0.0]]), 3.5, 13.9, source_id="in", successors=[1, 2]),
        LaneElement(np.array([[100.0, 0.0], [120.0, 0.0]]), 3.5, 8.0, source_id="straight", in_junction=True),
        LaneElement(
            np.array([[100.0, 0.0], [110.0, 10.0]]), 3.0, 8.0, LaneKind.BUS, "left", in_junction=True
        ),
    ]
    edges = [PolylineElement(np.array([[0.0, -1.75], [100.0, -1.75]]), source_id="curb")]
    stops = [StopLineElement(np.array([[95.0, -1.75], [95.0, 1.75]]), StopKind.STOP, [0], "s1")]
    lights = [TrafficLightElement(np.array([[98.0, -1.75], [98.0, 1.75]]), 2, [0], "tl1")]
    walks = [CrosswalkElement(np.array([[50.0, -2.0], [54.0, -2.0], [54.0, 2.0], [50.0, 2.0]]), "cw")]
    elements = MapElements(
        name="junction",
        source="hand",
        frame_origin=(650000.0, 6465000.0),
        crs="EPSG:3301",
        lanes=lanes,
        road_edges=edges,
        stop_lines=stops,
        traffic_lights=lights,
        crosswalks=walks,
    )
    return compile_map(elements)


def _assert_same(a: object, b: object, where: str = "RoadMap") -> None:
    assert type(a) is type(b), where
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if dataclasses.is_dataclass(x):
            _assert_same(x, y, f"{where}.{f.name}")
        elif isinstance(x, np.ndarray):
            assert x.dtype == y.dtype, f"{where}.{f.name}"
            np.testing.assert_array_equal(x, y, err_msg=f"{where}.{f.name}")
        else:
            assert x == y and type(x) is type(y), f"{where}.{f.name}"


def test_round_trip_identical(junction_map, tmp_path):
    path = save_roadmap(junction_map, tmp_path / "m.npz", source_sha256="ab" * 32, compile_params={"k": 1})
    loaded = load_roadmap(path, expect_source_sha="ab" * 32)
    _assert_same(junction_map, loaded)
    assert loaded.grid.shape == junction_map.grid.shape and isinstance(loaded.grid.shape[0], int)
    assert loaded.lanes.source_id.tolist() == ["in", "straight", "left"]
    assert loaded.origin.dtype == np.float64
    # loaded arrays are read-only like compiled ones
    with pytest.raises(ValueError):
        loaded.segments.mid[0, 0] = 1.0
    meta = read_meta(path)
    assert meta.format_version == FORMAT_VERSION and meta.source_sha256 == "ab" * 32
    assert meta.compile_params == {"k": 1, "max_segment_length": 10.0, "cell_size": 20.0}


def test_round_trip_straight(straight_map, tmp_path):
    _assert_same(straight_map, load_roadmap(save_roadmap(straight_map, tmp_path / "s.npz")))


def test_no_pickle_needed(junction_map, tmp_path):
    path = save_roadmap(junction_map, tmp_path / "m.npz")
    with np.load(path, allow_pickle=False) as npz:  # would raise on any object array
        assert all(npz[k].dtype != object for k in npz.files)


def _rewrite_meta(path, tmp_path, **changes):
    with np.load(path, allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    meta = json.loads(str(arrays["__meta__"][()]))
    meta.update(changes)
    arrays["__meta__"] = np.asarray(json.dumps(meta))
    out = tmp_path / "edited.npz"
    np.savez(out, **arrays)
    return out


def test_version_mismatch_names_file_and_versions(junction_map, tmp_path):
    path = save_roadmap(junction_map, tmp_path / "m.npz")
    old = _rewrite_meta(path, tmp_path, format_version=FORMAT_VERSION + 1)
    msg = f"has format version {FORMAT_VERSION + 1}, this selfplaydrive reads {FORMAT_VERSION}"
    with pytest.raises(MapError, match=msg) as info:
        load_roadmap(old)
    assert info.value.path == str(old) and "rebuild=True" in str(info.value)


def test_stale_source_sha(junction_map, tmp_path):
    path = save_roadmap(junction_map, tmp_path / "m.npz", source_sha256="1" * 64)
    with pytest.raises(MapError, match="stale"):
        load_roadmap(path, expect_source_sha="2" * 64)


@pytest.mark.parametrize("damage", ["truncate", "garbage", "flip", "empty"])
def test_corrupted_file_raises_map_error(junction_map, tmp_path, damage):
    path = save_roadmap(junction_map, tmp_path / "m.npz")
    data = path.read_bytes()
    if damage == "truncate":
        path.write_bytes(data[: len(data) // 2])
    elif damage == "garbage":
        path.write_bytes(b"this is not a zip file" * 10)
    elif damage == "flip":  # flip bytes inside the largest array's data: the zip CRC must catch it
        with zipfile.ZipFile(path) as z:
            info = max(z.infolist(), key=lambda i: i.file_size)
        data_start = info.header_offset + 30 + len(info.filename) + 128  # local header + npy header
        mid = data_start + (info.file_size - 128) // 2
        buf = bytearray(data)
        for i in range(mid, mid + 8):
            buf[i] ^= 0xFF
        path.write_bytes(bytes(buf))
    else:
        path.write_bytes(b"")
    with pytest.raises(MapError, match="CRC" if damage == "flip" else "corrupted") as info:
        load_roadmap(path)
    assert info.value.path == str(path)


def _flip_npy_header(path) -> None:
    """Flip one bit of the closing brace of the largest member's npy header dict ('}' -> '|'):
    numpy's header parser raises tokenize.TokenError before the zip CRC is checked (small
    members are read whole, so there the CRC catches the flip first)."""
    data = bytearray(path.read_bytes())
    with zipfile.ZipFile(path) as z:
        info = max(z.infolist(), key=lambda i: i.file_size)
    start = data.index(b"\x93NUMPY", info.header_offset)  # after the zip local header
    data[data.index(b"}", start)] ^= 0x01
    path.write_bytes(bytes(data))


def test_damaged_npy_header_raises_map_error(tmp_path):
    # a 20 km lane: 2,000 segments, so the largest member spans several zip read blocks
    lane = LaneElement(np.array([[0.0, 0.0], [20000.0, 0.0]]), 3.5, 13.9, source_id="long")
    path = save_roadmap(compile_map(MapElements(name="long", lanes=[lane])), tmp_path / "m.npz")
    _flip_npy_header(path)
    with pytest.raises(MapError, match="corrupted") as info:
        load_roadmap(path)
    assert info.value.path == str(path)
    assert "TokenError" in str(info.value)  # the cause is named, not swallowed


def test_wrong_entry_dtype_raises_map_error(junction_map, tmp_path):
    # a well-formed zip whose scalar entry cannot be converted (a string where a float belongs)
    path = save_roadmap(junction_map, tmp_path / "m.npz")
    with np.load(path, allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    arrays["max_segment_length"] = np.asarray("ten metres")
    np.savez(tmp_path / "bad.npz", **arrays)
    with pytest.raises(MapError, match=r"max_segment_length|corrupted") as info:
        load_roadmap(tmp_path / "bad.npz")
    assert info.value.path == str(tmp_path / "bad.npz")


def test_stale_temporary_is_removed_fresh_one_kept(junction_map, tmp_path):
    stale = tmp_path / ".m.npz.abc123.tmp"  # what save_roadmap leaves when killed mid-write
    fresh = tmp_path / ".m.npz.def456.tmp"  # a concurrent writer's file, still being written
    other = tmp_path / "notes.tmp"  # not ours: never touched
    for f in (stale, fresh, other):
        f.write_bytes(b"PK\x03\x04 partial")
    old = time.time() - cache.STALE_TMP_AGE - 60
    os.utime(stale, (old, old))
    os.utime(other, (old, old))
    save_roadmap(junction_map, tmp_path / "m.npz")
    assert sorted(p.name for p in tmp_path.iterdir()) == [".m.npz.def456.tmp", "m.npz", "notes.tmp"]


def test_missing_entry_and_inconsistent_offsets(junction_map, tmp_path):
    path = save_roadmap(junction_map, tmp_path / "m.npz")
    with np.load(path, allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    partial = dict(arrays)
    del partial["lanes.width"]
    np.savez(tmp_path / "partial.npz", **partial)
    with pytest.raises(MapError, match=r"lanes\.width"):
        load_roadmap(tmp_path / "partial.npz")
    broken = dict(arrays)
    broken["grid.cell_offsets"] = broken["grid.cell_offsets"].copy()
    broken["grid.cell_offsets"][-1] += 7  # points past the end of cell_items
    np.savez(tmp_path / "broken.npz", **broken)
    with pytest.raises(MapError, match=r"grid\.cell_offsets"):
        load_roadmap(tmp_path / "broken.npz")


def test_foreign_npz_refused(tmp_path):
    np.savez(tmp_path / "other.npz", a=np.zeros(3))
    with pytest.raises(MapError, match="not a selfplaydrive map cache"):
        load_roadmap(tmp_path / "other.npz")


def test_missing_file(tmp_path):
    with pytest.raises(MapError, match="not found"):
        load_roadmap(tmp_path / "nope.npz")


def test_atomic_write_keeps_old_file_on_failure(junction_map, straight_map, tmp_path, monkeypatch):
    path = save_roadmap(straight_map, tmp_path / "m.npz")
    before = path.read_bytes()

    def failing_savez(f, **arrays):
        f.write(b"PK\x03\x04 partial")  # the start of a zip, then the disk "fills up"
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(cache.np, "savez", failing_savez)
    with pytest.raises(MapError, match="No space left"):
        save_roadmap(junction_map, path)
    assert path.read_bytes() == before  # old cache untouched
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.npz"]  # no temporary left behind
    with pytest.raises(KeyboardInterrupt):  # an interrupt mid-write also leaves nothing partial
        monkeypatch.setattr(cache.np, "savez", lambda f, **a: (_ for _ in ()).throw(KeyboardInterrupt()))
        save_roadmap(junction_map, tmp_path / "new.npz")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.npz"]


def test_file_sha256(tmp_path):
    p = tmp_path / "f.txt"
    p.write_bytes(b"abc")
    # sha256("abc") from FIPS 180-2 appendix B.1
    assert cache.file_sha256(p) == "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
    with pytest.raises(MapError, match="cannot read"):
        cache.file_sha256(tmp_path / "missing.osm")


def test_saved_file_is_plain_zip(junction_map, tmp_path):
    path = save_roadmap(junction_map, tmp_path / "m.npz")
    with zipfile.ZipFile(path) as z:
        names = z.namelist()
        assert "__meta__.npy" in names and "lanes.centerlines.points.npy" in names
        assert all(i.compress_type == zipfile.ZIP_STORED for i in z.infolist())  # fast to load


def test_load_is_fast_on_a_large_map(tmp_path):
    # ~4000 lanes of 50 m (200 lane-km, well above Tartu's 16 km): loading stays in milliseconds
    rng = np.random.default_rng(0)
    starts = rng.uniform(0, 3000, size=(4000, 2))
    lanes = [
        LaneElement(s + np.array([[0.0, 0.0], [30.0, 0.0], [50.0, 5.0]]), 3.5, 13.9, source_id=f"L{i}")
        for i, s in enumerate(starts)
    ]
    m = compile_map(MapElements(name="big", lanes=lanes))
    path = save_roadmap(m, tmp_path / "big.npz")
    load_roadmap(path)
    t0 = time.perf_counter()
    for _ in range(5):
        load_roadmap(path)
    per_load = (time.perf_counter() - t0) / 5
    assert per_load < 0.25, f"cache load took {per_load * 1e3:.1f} ms"  # generous: shared CI cores
