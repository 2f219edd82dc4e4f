"""RoadMap compilation: segments, grid queries, validation errors."""

from __future__ import annotations

import numpy as np
import pytest

from selfplaydrive._sim.spatial import query_radius_batch
from selfplaydrive.errors import MapError
from selfplaydrive.maps import LaneElement, MapElements, SegmentType, compile_map
from selfplaydrive.maps.compile import cut_polyline


def test_segments_no_longer_than_max(straight_map):
    seg = straight_map.segments
    assert seg.length.max() <= straight_map.max_segment_length + 1e-4
    # 200 m straight lane cut into 10 m pieces: 20 segments per lane, 4 polylines
    assert len(seg) == 80
    lane = seg.type == SegmentType.LANE_CENTER
    assert np.isclose(seg.length[lane].sum(), 400.0, atol=1e-3)


def test_collinear_points_merged():
    pts = np.array([[0, 0], [1, 0.001], [2, 0], [3, -0.001], [4, 0]], dtype=float)
    s, e = cut_polyline(pts, max_len=10.0, tol=0.05)
    assert len(s) == 1
    np.testing.assert_allclose(e[0], [4, 0])


def test_lane_km_and_origin(straight_map):
    assert np.isclose(straight_map.vehicle_lane_km(), 0.4, atol=1e-6)
    # geometry is recentred; origin + local gives the input coordinates back
    pts = straight_map.lanes.centerlines[0].astype(np.float64) + straight_map.origin
    np.testing.assert_allclose(pts, [[0, 0], [200, 0]], atol=1e-4)


def test_grid_query_matches_brute_force(straight_map):
    rng = np.random.default_rng(0)
    lo, hi = straight_map.bounds[:2] - 20, straight_map.bounds[2:] + 20
    q = rng.uniform(lo, hi, size=(50, 2)).astype(np.float32)
    counts, idx = query_radius_batch(straight_map, q, 30.0)
    mid = straight_map.segments.mid
    for i, p in enumerate(q):
        brute = set(np.nonzero(np.sum((mid - p) ** 2, axis=1) <= 900.0)[0].tolist())
        assert set(idx[i, : counts[i]].tolist()) == brute
        assert set(straight_map.query_radius(float(p[0]), float(p[1]), 30.0).tolist()) == brute


def test_empty_map_raises():
    with pytest.raises(MapError, match="no lanes"):
        compile_map(MapElements(name="empty", source="empty.osm"))


def test_nan_lane_names_element():
    lane = LaneElement(np.array([[0.0, 0.0], [np.nan, 1.0]]), width=3.0, speed_limit=10.0, source_id="L42")
    with pytest.raises(MapError, match="L42"):
        compile_map(MapElements(name="bad", source="bad.osm", lanes=[lane]))


def test_dangling_successor_raises():
    lane = LaneElement(np.array([[0.0, 0.0], [10.0, 0.0]]), 3.0, 10.0, source_id="L1", successors=[5])
    with pytest.raises(MapError, match=r"L1.*lane index 5"):
        compile_map(MapElements(name="bad", lanes=[lane]))


def test_arrays_are_read_only(straight_map):
    with pytest.raises(ValueError):
        straight_map.segments.mid[0, 0] = 1.0
