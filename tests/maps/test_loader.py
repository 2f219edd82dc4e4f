"""`load_map`: dispatch by spec, cache reuse and automatic rebuilds, procedural specs."""

from __future__ import annotations

import logging
import os
import sys
import time
import types
import zipfile

import numpy as np
import pytest
from loadfile import ROOT, load_file
from sharedmaps import shared_map

from selfplaydrive.errors import MapError
from selfplaydrive.maps import LaneElement, MapElements, compile_map, loader
from selfplaydrive.maps.base import MapLoader
from selfplaydrive.maps.cache import load_roadmap, save_roadmap
from selfplaydrive.maps.loader import cache_path_for, load_map, parse_procedural_spec


class CountingLoader:
    """Fake file loader: one lane whose length is the file's byte count (so edits show)."""

    calls = 0

    def __init__(self, path, lane_length=None):
        self.path = path
        self.lane_length = lane_length

    def load(self):
        CountingLoader.calls += 1
        length = self.lane_length or float(len(self.path.read_bytes()))
        lane = LaneElement(np.array([[0.0, 0.0], [length, 0.0]]), 3.5, 13.9, source_id="only")
        return compile_map(MapElements(name=self.path.stem, source=str(self.path), lanes=[lane]))


@pytest.fixture
def fake_osm(tmp_path, monkeypatch):
    monkeypatch.setitem(loader._FILE_LOADERS, ".osm", ("selfplaydrive.maps.compile", CountingLoader))
    CountingLoader.calls = 0
    path = tmp_path / "town.osm"
    path.write_bytes(b"x" * 120)
    return path


def test_counting_loader_satisfies_protocol(fake_osm):
    assert isinstance(CountingLoader(fake_osm), MapLoader)


def test_second_load_hits_cache(fake_osm, tmp_path):
    cache_dir = tmp_path / "cache"
    first = load_map(fake_osm, cache_dir=cache_dir)
    second = load_map(str(fake_osm), cache_dir=cache_dir)
    assert CountingLoader.calls == 1
    assert np.isclose(second.vehicle_lane_km(), 0.12)
    np.testing.assert_array_equal(first.segments.mid, second.segments.mid)
    cached = cache_path_for(fake_osm, cache_dir)
    assert cached.parent == cache_dir and cached.name.startswith("town.") and cached.exists()
    load_map(fake_osm, cache_dir=cache_dir, rebuild=True)
    assert CountingLoader.calls == 2


def test_edited_source_rebuilds(fake_osm, tmp_path):
    load_map(fake_osm, cache_dir=tmp_path / "c")
    fake_osm.write_bytes(b"x" * 250)
    m = load_map(fake_osm, cache_dir=tmp_path / "c")
    assert CountingLoader.calls == 2 and np.isclose(m.vehicle_lane_km(), 0.25)


def test_loader_kwargs_are_part_of_the_key(fake_osm, tmp_path):
    a = load_map(fake_osm, cache_dir=tmp_path, lane_length=40.0)
    b = load_map(fake_osm, cache_dir=tmp_path, lane_length=60.0)
    c = load_map(fake_osm, cache_dir=tmp_path, lane_length=40.0)
    assert CountingLoader.calls == 2
    assert np.isclose(a.vehicle_lane_km(), 0.04) and np.isclose(b.vehicle_lane_km(), 0.06)
    assert np.isclose(c.vehicle_lane_km(), 0.04)
    assert cache_path_for(fake_osm, tmp_path, lane_length=40.0) != cache_path_for(fake_osm, tmp_path)


def test_code_change_rebuilds(fake_osm, tmp_path, monkeypatch):
    load_map(fake_osm, cache_dir=tmp_path)
    monkeypatch.setattr(loader, "_code_fingerprint", lambda: "edited loader code")
    load_map(fake_osm, cache_dir=tmp_path)
    assert CountingLoader.calls == 2 and len(list(tmp_path.glob("town.*.npz"))) == 2


def test_damaged_cache_is_rebuilt(fake_osm, tmp_path, caplog):
    load_map(fake_osm, cache_dir=tmp_path)
    cached = cache_path_for(fake_osm, tmp_path)
    cached.write_bytes(b"garbage")
    with caplog.at_level(logging.WARNING, logger="selfplaydrive.maps.loader"):
        m = load_map(fake_osm, cache_dir=tmp_path)
    assert CountingLoader.calls == 2 and np.isclose(m.vehicle_lane_km(), 0.12)
    assert "rebuilding map cache" in caplog.text and str(cached) in caplog.text
    load_roadmap(cached)  # replaced by a valid file


def test_cache_with_damaged_npy_header_is_rebuilt(fake_osm, tmp_path, caplog):
    # one flipped bit in an npy header made numpy raise tokenize.TokenError, which escaped the
    # loader and left the source map unloadable until the cache was deleted by hand
    load_map(fake_osm, cache_dir=tmp_path, lane_length=20000.0)  # 2,000 segments: large members
    cached = cache_path_for(fake_osm, tmp_path, lane_length=20000.0)
    data = bytearray(cached.read_bytes())
    with zipfile.ZipFile(cached) as z:
        info = max(z.infolist(), key=lambda i: i.file_size)  # small members hit the CRC first
    npy = data.index(b"\x93NUMPY", info.header_offset)  # after the zip local header
    data[data.index(b"}", npy)] ^= 0x01  # the header dict's closing brace: '}' -> '|'
    cached.write_bytes(bytes(data))
    with caplog.at_level(logging.WARNING, logger="selfplaydrive.maps.loader"):
        m = load_map(fake_osm, cache_dir=tmp_path, lane_length=20000.0)
    assert CountingLoader.calls == 2 and np.isclose(m.vehicle_lane_km(), 20.0)
    assert "rebuilding map cache" in caplog.text and str(fake_osm) in caplog.text
    assert "TokenError" in caplog.text
    load_roadmap(cached)  # replaced by a valid file


def test_any_cache_read_error_rebuilds(fake_osm, tmp_path, monkeypatch, caplog):
    load_map(fake_osm, cache_dir=tmp_path)

    def broken(*args, **kwargs):
        raise RuntimeError("unexpected failure inside the reader")

    monkeypatch.setattr(loader.cache, "load_roadmap", broken)
    with caplog.at_level(logging.WARNING, logger="selfplaydrive.maps.loader"):
        m = load_map(fake_osm, cache_dir=tmp_path)
    assert CountingLoader.calls == 2 and np.isclose(m.vehicle_lane_km(), 0.12)
    assert "unexpected failure inside the reader" in caplog.text


def test_killed_writer_temporary_is_cleaned(fake_osm, tmp_path):
    cached = cache_path_for(fake_osm, tmp_path)
    tmp_path.mkdir(exist_ok=True)
    # a writer killed after mkstemp leaves its temporary and no cache; one of an older map too
    own = tmp_path / f".{cached.name}.k1ll3d.tmp"
    older = tmp_path / ".gone.0123456789abcdef0123.npz.x7.tmp"
    for f in (own, older):
        f.write_bytes(b"PK\x03\x04")
        stamp = time.time() - 3600
        os.utime(f, (stamp, stamp))
    load_map(fake_osm, cache_dir=tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir() if p.name != "town.osm") == [cached.name]


def test_env_var_sets_default_cache_dir(fake_osm, tmp_path, monkeypatch):
    monkeypatch.setenv("SELFPLAYDRIVE_CACHE_DIR", str(tmp_path / "envcache"))
    load_map(fake_osm)
    assert len(list((tmp_path / "envcache").glob("town.*.npz"))) == 1


def test_no_cache_writes_nothing(fake_osm, tmp_path):
    load_map(fake_osm, cache_dir=tmp_path / "c", use_cache=False)
    load_map(fake_osm, cache_dir=tmp_path / "c", use_cache=False)
    assert CountingLoader.calls == 2 and not (tmp_path / "c").exists()


def test_unwritable_cache_warns_and_still_loads(fake_osm, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    with pytest.warns(UserWarning, match="could not write the map cache"):
        m = load_map(fake_osm, cache_dir=blocker / "sub")
    assert np.isclose(m.vehicle_lane_km(), 0.12)


def test_unknown_extension_lists_supported(tmp_path):
    p = tmp_path / "map.geojson"
    p.write_text("{}")
    with pytest.raises(
        MapError, match=r"unsupported map extension '\.geojson'.*\.osm.*\.xodr.*\.npz"
    ) as info:
        load_map(p)
    assert info.value.path == str(p)


def test_missing_file(tmp_path):
    with pytest.raises(MapError, match="not found"):
        load_map(tmp_path / "nope.xodr")


def test_npz_spec_and_passthrough(straight_map, tmp_path):
    path = save_roadmap(straight_map, tmp_path / "s.npz")
    m = load_map(path)
    np.testing.assert_array_equal(m.lanes.centerlines.points, straight_map.lanes.centerlines.points)
    assert load_map(straight_map) is straight_map
    with pytest.raises(MapError, match="takes no loader arguments"):
        load_map(path, max_segment_length=5.0)


def test_parse_procedural_spec():
    assert parse_procedural_spec("procedural:seed=3,size=800") == {"seed": 3, "size": 800}
    assert parse_procedural_spec("procedural: seed=1, lights=false, scale=0.5, style=grid") == {
        "seed": 1,
        "lights": False,
        "scale": 0.5,
        "style": "grid",
    }
    assert parse_procedural_spec("procedural") == {}
    with pytest.raises(MapError, match="not key=value"):
        parse_procedural_spec("procedural:seed3")
    with pytest.raises(MapError, match="repeats key 'seed'"):
        parse_procedural_spec("procedural:seed=1,seed=2")


@pytest.fixture
def fake_procedural(monkeypatch, straight_map):
    calls = []

    class ProceduralTownLoader:
        def __init__(self, seed, size=500.0):
            calls.append((seed, size))

        def load(self):
            return straight_map

    mod = types.ModuleType("selfplaydrive.maps.procedural")
    mod.ProceduralTownLoader = ProceduralTownLoader
    mod.load_default_map = lambda: straight_map
    monkeypatch.setitem(sys.modules, "selfplaydrive.maps.procedural", mod)
    return calls


def test_procedural_and_default_dispatch(fake_procedural, straight_map):
    assert load_map("procedural:seed=3,size=800") is straight_map
    assert load_map("procedural:seed=4", size=300.0) is straight_map
    assert load_map("default") is straight_map
    assert fake_procedural == [(3, 800), (4, 300.0)]
    with pytest.raises(MapError, match=r"accepted: seed, size"):
        load_map("procedural:seed=3,colour=red")


# ------------------------------------------------------------------------------ real loaders


def _need(module: str, name: str) -> None:
    """Skip (with the reason) while another part of the project is not there yet."""
    mod = pytest.importorskip(module, reason=f"{module} not built yet")
    if not hasattr(mod, name):
        pytest.skip(f"{module}.{name} not built yet")


@pytest.mark.shared_maps
def test_tartu_through_cache(tmp_path):
    _need("selfplaydrive.maps.lanelet2", "Lanelet2Loader")
    from selfplaydrive.maps.lanelet2 import Lanelet2Loader

    path = shared_map("tartu_lanelet2/tartu_demo_l.osm")
    assert isinstance(Lanelet2Loader(path), MapLoader)
    m = load_map(path, cache_dir=tmp_path)
    assert abs(m.vehicle_lane_km() - 15.99) < 0.05
    assert len(list(tmp_path.glob("tartu_demo_l.*.npz"))) == 1
    again = load_map(path, cache_dir=tmp_path)
    np.testing.assert_array_equal(again.segments.mid, m.segments.mid)
    assert again.light_lines.points.shape == m.light_lines.points.shape


@pytest.mark.shared_maps
def test_opendrive_through_cache(tmp_path):
    _need("selfplaydrive.maps.opendrive", "OpenDriveLoader")
    from selfplaydrive.maps.opendrive import OpenDriveLoader

    path = shared_map("carla_opendrive/Town01.xodr")
    assert isinstance(OpenDriveLoader(path), MapLoader)
    m = load_map(path, cache_dir=tmp_path)
    assert abs(m.vehicle_lane_km() - 6.4) < 0.3  # shared/maps/README: 6.4 km of driving lanes
    np.testing.assert_array_equal(load_map(path, cache_dir=tmp_path).segments.mid, m.segments.mid)


def test_real_default_map():
    _need("selfplaydrive.maps.procedural", "load_default_map")
    m = load_map("default")
    assert m.vehicle_lane_km() > 0.5 and len(m.light_lines) > 0


def test_bench_maps_smoke(straight_map, tmp_path, capsys):
    """benchmarks/bench_maps.py runs end to end (tiny sizes), so it cannot rot unnoticed."""

    bench = load_file(ROOT / "benchmarks" / "bench_maps.py", "bench_maps")
    path = save_roadmap(straight_map, tmp_path / "s.npz")
    argv = ["--map", str(path), "--repeat", "1", "--load-repeat", "2", "--queries", "500", "--radius", "30"]
    assert bench.main(argv) == 0
    out = capsys.readouterr().out
    assert "compile" in out and "cache load" in out and out.count("us/query") == 4
    # query points lie on the two 200 m lanes (10 m segments, midpoints at 5, 15, ... m); even at
    # a lane end r = 30 m reaches 3 midpoints on each of the 4 parallel lines (2 lanes, 2 edges
    # at most 5.25 m away), and never all 80 segments
    q = bench.bench_queries(straight_map, bench.random_points(straight_map, 200, 0, True), 30.0)
    assert 12 <= q["mean_found"] < 80 and q["share_empty"] == 0.0
