"""Routing (paper section 2.2): random legal routes, dead ends, waypoint spacing, kernels vs references."""

from __future__ import annotations

import networkx as nx
import numpy as np
import pytest

from selfplaydrive.maps import LaneElement, LaneKind, MapElements, compile_map
from selfplaydrive.maps.routing import (
    MIN_CHANGE_LENGTH,
    Route,
    _empty_batch,
    batch_waypoints,
    lane_graph,
    largest_scc_share,
    random_route,
    route_tables,
    route_waypoints,
    sample_routes,
    waypoint_times,
)
from selfplaydrive.scenario._testmaps import grid_elements
from selfplaydrive.testing.spawn_reference import (
    batch_waypoints_reference,
    hash_uniforms,
    lane_points_reference,
    sample_routes_reference,
)


def _chain(lengths, speeds, bike_branch: bool = False):
    """Lanes along +x, each the only successor of the one before; the last one dead-ends."""
    lanes, x = [], 0.0
    for i, (length, v) in enumerate(zip(lengths, speeds, strict=True)):
        succ = [i + 1] if i + 1 < len(lengths) else []
        lanes.append(
            LaneElement(np.array([[x, 0.0], [x + length, 0.0]]), 3.5, v, source_id=f"l{i}", successors=succ)
        )
        x += length
    if bike_branch:  # a bicycle lane that also follows lane 0: vehicles must never take it
        lanes.append(
            LaneElement(
                np.array([[lengths[0], 0.0], [lengths[0], 50.0]]),
                1.5,
                5.0,
                kind=LaneKind.BICYCLE,
                source_id="bike",
            )
        )
        lanes[0].successors.append(len(lanes) - 1)
    return compile_map(MapElements(name="chain", lanes=lanes))


@pytest.fixture(scope="module")
def grid2():
    return compile_map(grid_elements(nx=3, ny=3, block=80.0, lanes_per_dir=2))


def test_networkx_graph_kept():
    m = _chain([100.0, 100.0], [10.0, 10.0])
    g = lane_graph(m)
    assert isinstance(g, nx.DiGraph) and list(g.edges) == [(0, 1)]
    assert largest_scc_share(m) == pytest.approx(0.5)


def test_route_follows_chain_and_stops_at_dead_end():
    m = _chain([100.0, 80.0, 60.0], [10.0, 10.0, 10.0])
    route = random_route(m, 0, np.random.default_rng(0), start_s=30.0, horizon_s=1000.0)
    assert route.lanes.tolist() == [0, 1, 2]
    assert route.dead_end
    np.testing.assert_allclose(route.s_start, [30.0, 0.0, 0.0])
    np.testing.assert_allclose(route.s_end, [100.0, 80.0, 60.0], rtol=1e-6)
    # (70 + 80 + 60) m at 10 m/s
    assert route.duration(route_tables(m).speed) == pytest.approx(21.0, rel=1e-6)


def test_route_stops_at_horizon():
    m = _chain([100.0, 100.0, 100.0, 100.0], [10.0] * 4)
    route = random_route(m, 0, np.random.default_rng(0), horizon_s=15.0)
    # lane 0 takes 10 s (< 15), lane 1 ends at 20 s (>= 15): stop there
    assert route.lanes.tolist() == [0, 1]
    assert not route.dead_end


def test_route_never_enters_bicycle_lane():
    m = _chain([100.0, 100.0], [10.0, 10.0], bike_branch=True)
    for seed in range(20):
        route = random_route(m, 0, np.random.default_rng(seed), horizon_s=100.0)
        assert route.lanes.tolist() == [0, 1]


def test_random_routes_use_only_legal_moves(grid2):
    lanes = grid2.lanes
    t = route_tables(grid2)
    rng = np.random.default_rng(1)
    start = rng.integers(0, len(lanes), 300)
    batch = sample_routes(t, start, np.zeros(300), np.full(300, 60.0), rng, lane_change_prob=0.5)
    n_changes = 0
    for a in range(300):
        r = batch.route(a)
        assert r.lanes[0] == start[a]
        for i in range(len(r.lanes) - 1):
            here, nxt = int(r.lanes[i]), int(r.lanes[i + 1])
            if r.change[i]:
                n_changes += 1
                legal = {
                    int(lanes.left[here]) if lanes.left_legal[here] else -2,
                    int(lanes.right[here]) if lanes.right_legal[here] else -2,
                }
                assert nxt in legal
                assert r.s_end[i] - r.s_start[i] >= MIN_CHANGE_LENGTH / 2 - 1e-9
            else:
                assert nxt in lanes.successors(here).tolist()
                assert r.s_end[i] == pytest.approx(t.length[here])
        if r.dead_end:
            assert len(lanes.successors(int(r.lanes[-1]))) == 0
        else:
            assert r.duration(t.speed) >= 60.0 - 1e-9
    assert n_changes > 20  # lane changes do happen on a two-lane grid


def test_dead_ends_reached_on_grid_with_stubs():
    m = compile_map(grid_elements(nx=2, ny=2, block=80.0))
    t = route_tables(m)
    rng = np.random.default_rng(2)
    batch = sample_routes(t, rng.integers(0, len(m.lanes), 200), np.zeros(200), np.full(200, 500.0), rng)
    assert batch.dead_end.mean() > 0.9  # 500 s of driving always ends at a border stub
    last = [batch.route(a).lanes[-1] for a in range(200) if batch.dead_end[a]]
    assert all(len(m.lanes.successors(int(lane))) == 0 for lane in last)


def test_kernel_matches_numpy_reference(grid2):
    t = route_tables(grid2)
    rng = np.random.default_rng(3)
    a = 150
    lane = rng.integers(0, len(t.length), a)
    s = rng.uniform(-0.2, 1.2, a) * t.length[lane]
    h = rng.uniform(1.0, 80.0, a)
    key = 0x1234_5678_9ABC_DEF0
    ref = sample_routes_reference(t, lane, s, h, key, lane_change_prob=0.4)
    from selfplaydrive._sim.lanes import walk_routes

    out = _empty_batch(a, 128)
    walk_routes(
        t.succ_offsets,
        t.succ_index,
        t.change_left,
        t.change_right,
        t.length,
        t.speed,
        lane.astype(np.int64),
        s,
        h,
        key,
        0.4,
        MIN_CHANGE_LENGTH,
        True,
        out.lanes,
        out.s_start,
        out.s_end,
        out.change,
        out.t_end,
        out.dead_end,
    )
    for field in ("lanes", "s_start", "s_end", "change", "t_end", "dead_end"):
        np.testing.assert_array_equal(getattr(out, field), getattr(ref, field), err_msg=field)


def test_hash_uniforms_kernel_matches_numpy_and_is_uniform():
    from selfplaydrive._sim.lanes import hash_uniforms as kernel_uniforms

    u = hash_uniforms(2**63 - 12345, 40, 3000)
    np.testing.assert_array_equal(kernel_uniforms(2**63 - 12345, 40, 3000), u)
    assert u.min() >= 0.0 and u.max() < 1.0
    np.testing.assert_allclose(np.histogram(u, bins=10, range=(0, 1))[0] / u.size, 0.1, atol=0.005)
    # neighbouring keys, agents and draws are uncorrelated
    assert abs(np.corrcoef(u[0], u[1])[0, 1]) < 0.05
    assert abs(np.corrcoef(u[:, :-1].ravel(), u[:, 1:].ravel())[0, 1]) < 0.02
    assert abs(np.corrcoef(u.ravel(), hash_uniforms(2**63 - 12344, 40, 3000).ravel())[0, 1]) < 0.02


def test_lane_points_kernel_matches_reference(grid2):
    t = route_tables(grid2)
    rng = np.random.default_rng(5)
    lane = rng.integers(0, len(t.length), 2000)
    s = rng.uniform(-0.1, 1.1, 2000) * t.length[lane]
    xy, h = t.points(lane, s)
    xy_ref, h_ref = lane_points_reference(t, lane, s)
    np.testing.assert_allclose(xy, xy_ref, atol=1e-9)
    np.testing.assert_allclose(h, h_ref, atol=1e-12)


def test_points_on_a_straight_lane():
    m = _chain([100.0], [10.0])
    xy, h = route_tables(m).points(np.array([0, 0, 0]), np.array([25.0, -5.0, 130.0]))
    x0 = float(m.lanes.centerlines[0][0, 0])
    np.testing.assert_allclose(xy[:, 0] - x0, [25.0, 0.0, 100.0], atol=1e-4)
    np.testing.assert_allclose(h, 0.0, atol=1e-7)


def test_waypoints_exact_spacing_without_jitter():
    # 10 m/s and 5 s gaps: waypoints every 50 m from the start position
    m = _chain([1000.0], [10.0])
    wps, n = route_waypoints(m, [0], 20.0, np.random.default_rng(0), spacing_jitter=0.0)
    x0 = float(m.lanes.centerlines[0][0, 0])
    assert n == 8
    np.testing.assert_allclose(wps[:, 0] - x0, 20.0 + 50.0 * np.arange(1, 9), atol=1e-3)


def test_waypoints_average_50_m_apart_with_jitter():
    m = _chain([2000.0], [10.0])
    gaps = []
    for seed in range(300):
        wps, n = route_waypoints(m, [0], 0.0, np.random.default_rng(seed))
        assert n == 8
        x = np.concatenate([[m.lanes.centerlines[0][0, 0]], wps[:, 0]])
        gaps.append(np.diff(x))
    gaps = np.concatenate(gaps)
    assert gaps.min() >= 25.0 - 1e-3 and gaps.max() <= 75.0 + 1e-3  # 5 s * U(0.5, 1.5) at 10 m/s
    assert gaps.mean() == pytest.approx(50.0, abs=1.0)


def test_waypoints_follow_each_lanes_speed_limit():
    # lane 0: 100 m at 10 m/s (10 s); lane 1: 1000 m at 20 m/s. Gaps of exactly 5 s:
    # t=5 -> 50 m on lane 0, t=10 -> end of lane 0, t=15 -> 100 m into lane 1, t=20 -> 200 m ...
    m = _chain([100.0, 1000.0], [10.0, 20.0])
    wps, n = route_waypoints(m, [0, 1], 0.0, np.random.default_rng(0), max_waypoints=4, spacing_jitter=0.0)
    x0 = float(m.lanes.centerlines[0][0, 0])
    np.testing.assert_allclose(wps[:, 0] - x0, [50.0, 100.0, 200.0, 300.0], atol=1e-3)
    assert n == 4


def test_short_route_gets_fewer_waypoints_padded_with_last():
    m = _chain([120.0], [10.0])  # 12 s of route: waypoints at 5 and 10 s only
    wps, n = route_waypoints(m, [0], 0.0, np.random.default_rng(0), spacing_jitter=0.0)
    x0 = float(m.lanes.centerlines[0][0, 0])
    assert n == 2
    np.testing.assert_allclose(wps[:2, 0] - x0, [50.0, 100.0], atol=1e-3)
    np.testing.assert_array_equal(wps[2:], np.repeat(wps[1:2], 6, axis=0))


def test_route_shorter_than_first_gap_gets_its_end_as_waypoint():
    m = _chain([30.0], [10.0])  # 3 s < 5 s
    wps, n = route_waypoints(m, [0], 0.0, np.random.default_rng(0), spacing_jitter=0.0)
    assert n == 1
    assert wps[0, 0] - float(m.lanes.centerlines[0][0, 0]) == pytest.approx(30.0, abs=1e-3)


def test_route_waypoints_accepts_route_objects():
    m = _chain([100.0, 100.0], [10.0, 10.0])
    route = Route(np.array([0, 1]), np.array([0.0, 0.0]), np.array([100.0, 100.0]), np.zeros(2, bool), True)
    wps, n = route_waypoints(m, route, 10.0, np.random.default_rng(0), spacing_jitter=0.0)
    x0 = float(m.lanes.centerlines[0][0, 0])
    assert n == 3
    np.testing.assert_allclose(wps[:3, 0] - x0, [60.0, 110.0, 160.0], atol=1e-3)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"spacing_s": 0.0}, "spacing_s"),
        ({"spacing_jitter": 1.0}, "spacing_jitter"),
        ({"max_waypoints": 0}, "max_waypoints"),
    ],
)
def test_route_waypoints_rejects_bad_settings(kwargs, match):
    m = _chain([100.0], [10.0])
    with pytest.raises(ValueError, match=match):
        route_waypoints(m, [0], 0.0, np.random.default_rng(0), **kwargs)


def test_bad_lanes_raise_clear_errors():
    m = _chain([100.0], [10.0])
    with pytest.raises(ValueError, match=r"start_lane 5 out of range \[0, 1\)"):
        random_route(m, 5, np.random.default_rng(0))
    with pytest.raises(ValueError, match="route lane indices"):
        route_waypoints(m, [3], 0.0, np.random.default_rng(0))
    with pytest.raises(ValueError, match="route has no lanes"):
        route_waypoints(m, [], 0.0, np.random.default_rng(0))


def test_routes_are_deterministic(grid2):
    a = random_route(grid2, 3, np.random.default_rng(9), horizon_s=60.0, lane_change_prob=0.3)
    b = random_route(grid2, 3, np.random.default_rng(9), horizon_s=60.0, lane_change_prob=0.3)
    np.testing.assert_array_equal(a.lanes, b.lanes)
    np.testing.assert_array_equal(a.s_end, b.s_end)


def test_waypoint_kernel_matches_reference(grid2):
    t = route_tables(grid2)
    rng = np.random.default_rng(6)
    a = 200
    lane = rng.integers(0, len(t.length), a)
    s = rng.uniform(0.0, 1.0, a) * t.length[lane]
    times = waypoint_times(rng, a, 8, 5.0, 0.5)
    times[:20] *= 100.0  # some routes end (horizon or max pieces) before their waypoints
    routes = sample_routes(t, lane, s, times[:, -1] * rng.uniform(0.2, 1.0, a), rng, lane_change_prob=0.3)
    xy, n = batch_waypoints(t, routes, times)
    xy_ref, n_ref = batch_waypoints_reference(t, routes, times)
    np.testing.assert_array_equal(n, n_ref)
    np.testing.assert_array_equal(xy, xy_ref)
    assert n.min() >= 1 and (n >= 4).any() and (n == 1).any()
