"""`selfplaydrive map info|render`: exact JSON keys and hand-computed values, exit codes."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from sharedmaps import shared_map

from selfplaydrive.cli import MAP_INFO_KEYS, main
from selfplaydrive.maps import (
    CrosswalkElement,
    LaneElement,
    LaneKind,
    MapElements,
    PolylineElement,
    StopKind,
    StopLineElement,
    TrafficLightElement,
    compile_map,
)
from selfplaydrive.maps.cache import save_roadmap


@pytest.fixture
def hand_map(tmp_path):
    """200 m straight lane, a 50*sqrt(2) m diagonal successor, a 30 m bicycle lane (not counted
    in lane_km), a 200 m curb, one stop line, two traffic lights, one crosswalk."""
    lanes = [
        LaneElement(np.array([[0.0, 0.0], [200.0, 0.0]]), 3.5, 13.9, source_id="east", successors=[1]),
        LaneElement(np.array([[200.0, 0.0], [250.0, 50.0]]), 3.5, 13.9, source_id="diag"),
        LaneElement(np.array([[0.0, 5.0], [30.0, 5.0]]), 1.5, 5.0, LaneKind.BICYCLE, "bike"),
    ]
    edges = [PolylineElement(np.array([[0.0, -1.75], [200.0, -1.75]]), source_id="curb")]
    stops = [StopLineElement(np.array([[190.0, -1.75], [190.0, 1.75]]), StopKind.YIELD, [0])]
    lights = [
        TrafficLightElement(np.array([[195.0, -1.75], [195.0, 1.75]]), 0, [0]),
        TrafficLightElement(np.array([[10.0, 4.0], [10.0, 6.0]]), 1, [2]),
    ]
    walks = [CrosswalkElement(np.array([[100.0, -2.0], [104.0, -2.0], [104.0, 2.0], [100.0, 2.0]]))]
    m = compile_map(
        MapElements(
            name="hand",
            lanes=lanes,
            road_edges=edges,
            stop_lines=stops,
            traffic_lights=lights,
            crosswalks=walks,
        )
    )
    return save_roadmap(m, tmp_path / "hand.npz")


def test_info_json_keys_and_values(hand_map, capsys):
    assert main(["map", "info", str(hand_map), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert list(info) == list(MAP_INFO_KEYS)
    assert set(info) == {
        "lane_km",
        "num_lanes",
        "num_traffic_light_stop_lines",
        "num_stop_lines",
        "num_crosswalks",
        "road_edge_km",
        "bounds",
    }
    # (200 + 50 * sqrt(2)) m of vehicle lanes; the bicycle lane does not count
    assert info["lane_km"] == pytest.approx((200 + 50 * np.sqrt(2)) / 1000, abs=1e-4)
    assert info["num_lanes"] == 3
    assert info["num_traffic_light_stop_lines"] == 2
    assert info["num_stop_lines"] == 1
    assert info["num_crosswalks"] == 1
    assert info["road_edge_km"] == pytest.approx(0.2)
    # lane bbox x 0..250, y 0..50 -> recentred by (125, 25); crosswalk reaches y = -2
    assert info["bounds"] == [-125.0, -27.0, 125.0, 25.0]


def test_info_text(hand_map, capsys):
    assert main(["map", "info", str(hand_map)]) == 0
    out = capsys.readouterr().out
    for key in MAP_INFO_KEYS:
        assert key in out
    assert "num_signal_groups              2" in out


def test_render_writes_png(hand_map, tmp_path, capsys):
    out = tmp_path / "sub" / "hand.png"
    assert main(["map", "render", str(hand_map), "-o", str(out), "--arrows", "--dpi", "40"]) == 0
    data = out.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 2000
    assert f"wrote {out}" in capsys.readouterr().out


def test_render_region(hand_map, tmp_path):
    out = tmp_path / "crop.png"
    assert main(["map", "render", str(hand_map), "-o", str(out), "--region", "-50", "-30", "50", "10"]) == 0
    assert out.stat().st_size > 1000


def test_render_bad_region_is_usage_error(hand_map, tmp_path, capsys):
    out = tmp_path / "x.png"
    assert main(["map", "render", str(hand_map), "-o", str(out), "--region", "10", "0", "5", "20"]) == 2
    assert "xmin < xmax" in capsys.readouterr().err
    assert not out.exists()


def test_missing_map_exit_1(tmp_path, capsys):
    assert main(["map", "info", str(tmp_path / "nope.osm")]) == 1
    err = capsys.readouterr().err
    assert "not found" in err and "nope.osm" in err


def test_unsupported_extension_exit_1(tmp_path, capsys):
    bad = tmp_path / "m.txt"
    bad.write_text("")
    assert main(["map", "info", str(bad)]) == 1
    assert ".osm" in capsys.readouterr().err


def test_info_default_spec(straight_map, monkeypatch, capsys):
    """PATH accepts 'default' (the bundled procedural town), dispatched through load_map."""
    import types

    fake = types.ModuleType("selfplaydrive.maps.procedural")
    fake.load_default_map = lambda: straight_map
    monkeypatch.setitem(sys.modules, "selfplaydrive.maps.procedural", fake)
    assert main(["map", "info", "default", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["num_lanes"] == 2 and info["lane_km"] == pytest.approx(0.4)  # two 200 m lanes


def test_unknown_command_exit_2(capsys):
    assert main(["drive"]) == 2
    err = capsys.readouterr().err
    assert "unknown command 'drive'" in err and "valid choices:" in err
    assert all(name in err for name in ("map", "train", "render", "bench"))


def test_unknown_map_action_exit_2(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["map", "paint", "x.osm"])
    assert exc.value.code == 2
    assert "invalid choice: 'paint'" in capsys.readouterr().err


def test_no_arguments_prints_usage(capsys):
    assert main([]) == 2
    assert "commands:" in capsys.readouterr().err
    assert main(["--help"]) == 0


def test_console_script_entry_point(hand_map):
    """The installed `selfplaydrive` script runs `main` (pyproject [project.scripts])."""
    proc = subprocess.run(
        [sys.executable, "-m", "selfplaydrive.cli", "map", "info", str(hand_map), "--json"],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["num_lanes"] == 3


@pytest.mark.shared_maps
def test_info_tartu(tmp_path, capsys):
    pytest.importorskip("selfplaydrive.maps.lanelet2", reason="Lanelet2 loader not built yet")
    path = shared_map("tartu_lanelet2/tartu_demo_l.osm")
    assert main(["map", "info", str(path), "--json", "--cache-dir", str(tmp_path)]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["lane_km"] == pytest.approx(15.99, abs=0.05)  # shared/maps/README: 15.99 km
    assert info["num_crosswalks"] == 48
    # Tartu is 2.0 x 3.2 km (shared/maps/README)
    xmin, ymin, xmax, ymax = info["bounds"]
    assert 1800 < xmax - xmin < 2300 and 3000 < ymax - ymin < 3500
