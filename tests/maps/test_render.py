"""Map renderer: lane polygons, what gets drawn, region crop, PNG output."""

from __future__ import annotations

import matplotlib.colors
import matplotlib.image
import numpy as np
import pytest
from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.figure import Figure
from sharedmaps import shared_map

from selfplaydrive.maps import LaneElement, MapElements, StopKind, StopLineElement, compile_map
from selfplaydrive.render import draw_map, lane_polygons, render_map


def test_lane_polygon_of_straight_lane(straight_map):
    # lanes y = 0 and y = 3.5, x 0..200 -> recentred by round((100, 1.75)) = (100, 2)
    poly = lane_polygons(straight_map, [0])[0]
    expected = [[-100, -0.25], [100, -0.25], [100, -3.75], [-100, -3.75]]  # width 3.5: +-1.75
    np.testing.assert_allclose(poly, expected, atol=1e-5)


def test_lane_polygon_keeps_width_on_a_bend():
    lane = LaneElement(np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]]), 2.0, 10.0)
    m = compile_map(MapElements(name="bend", lanes=[lane]))
    poly = lane_polygons(m)[0] + m.origin  # back to input coordinates
    # ends are offset 1 m along the end segments' normals; the corner is the miter point where
    # the left offset lines y = 1 and x = 9 meet, and the right side's miter is (11, -1)
    np.testing.assert_allclose(poly[:3], [[0, 1], [9, 1], [9, 10]], atol=1e-5)
    np.testing.assert_allclose(poly[3:], [[11, 10], [11, -1], [0, -1]], atol=1e-5)


@pytest.fixture
def gap_map():
    """Lane 0 -> lane 1 starts 5 m after lane 0 ends (a gapped link); lane 1 is a dead end."""
    lanes = [
        LaneElement(np.array([[0.0, 0.0], [50.0, 0.0]]), 3.5, 10.0, successors=[1]),
        LaneElement(np.array([[55.0, 0.0], [100.0, 0.0]]), 3.5, 10.0),
    ]
    stops = [StopLineElement(np.array([[45.0, -1.75], [45.0, 1.75]]), StopKind.STOP, [0])]
    return compile_map(MapElements(name="gap", lanes=lanes, stop_lines=stops))


def _collections(ax):
    return [c for c in ax.collections if isinstance(c, LineCollection | PolyCollection)]


def test_arrows_show_gap_and_dead_end(gap_map):
    ax = Figure().add_subplot()
    draw_map(ax, gap_map, arrows=True)
    magenta = [
        c
        for c in ax.collections
        if isinstance(c, LineCollection)
        and np.allclose(c.get_colors()[0], matplotlib.colors.to_rgba("magenta"))
    ]
    assert len(magenta) == 1
    seg = magenta[0].get_segments()[0] + gap_map.origin
    np.testing.assert_allclose(seg, [[50, 0], [55, 0]], atol=1e-4)
    crosses = [ln for ln in ax.lines if ln.get_marker() == "x"]
    assert len(crosses) == 1 and np.allclose(np.c_[crosses[0].get_data()] + gap_map.origin, [[100, 0]])
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "stop line" in labels and "lane without successor" in labels and "yield line" not in labels


def test_without_arrows_no_graph_overlay(gap_map):
    ax = Figure().add_subplot()
    draw_map(ax, gap_map)
    assert not ax.lines and len(ax.patches) == 0
    assert all(
        not np.allclose(c.get_colors()[0], matplotlib.colors.to_rgba("magenta"))
        for c in ax.collections
        if isinstance(c, LineCollection)
    )


def test_region_sets_limits_and_aspect(straight_map):
    ax = Figure().add_subplot()
    draw_map(ax, straight_map, region=(-20, -10, 30, 15), legend=False)
    assert ax.get_xlim() == (-20, 30) and ax.get_ylim() == (-10, 15)
    assert ax.get_aspect() == 1.0 and ax.get_legend() is None


@pytest.mark.parametrize("region", [(10, 0, 5, 20), (0, 0, 1), (0, np.nan, 1, 1)])
def test_bad_region_raises(straight_map, region):
    with pytest.raises(ValueError, match="region"):
        draw_map(Figure().add_subplot(), straight_map, region=region)


def test_region_outside_draws_nothing_but_works(straight_map):
    ax = Figure().add_subplot()
    draw_map(ax, straight_map, region=(5000, 5000, 5100, 5100), arrows=True)
    assert _collections(ax) == []


def test_render_map_png_size(straight_map, tmp_path):
    out = render_map(straight_map, tmp_path / "s.png", dpi=50, size=4.0)
    img = matplotlib.image.imread(out)
    assert img.ndim == 3 and img.shape[1] > 150  # 4 in * 50 dpi of map plus legend
    with pytest.raises(ValueError, match="dpi"):
        render_map(straight_map, tmp_path / "t.png", dpi=0)


@pytest.mark.shared_maps
def test_render_tartu(tmp_path):
    from selfplaydrive.maps.loader import load_map

    pytest.importorskip("selfplaydrive.maps.lanelet2", reason="Lanelet2 loader not built yet")
    m = load_map(shared_map("tartu_lanelet2/tartu_demo_l.osm"), cache_dir=tmp_path)
    out = render_map(m, tmp_path / "tartu.png", arrows=True, dpi=60)
    assert out.stat().st_size > 20_000
