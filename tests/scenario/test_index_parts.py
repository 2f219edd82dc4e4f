"""Per-map index, placement helpers, vehicle sizes, lights and pedestrians of the spawner."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from selfplaydrive.errors import ConfigError
from selfplaydrive.maps.routing import MIN_CHANGE_LENGTH
from selfplaydrive.scenario.index import CellIndex, MapIndex, map_index
from selfplaydrive.scenario.lights import LightSampler
from selfplaydrive.scenario.pedestrians import PATH_POINTS, PedestrianSampler
from selfplaydrive.scenario.placement import (
    greedy_separated,
    roadside_offset,
    sample_on_chunks,
    sample_region,
)
from selfplaydrive.scenario.spawner import STATIC_CLEAR_AHEAD, STATIC_HEADWAY, PaperSpawner
from selfplaydrive.scenario.types import Scenario
from selfplaydrive.scenario.vehicles import DEFAULT_CATEGORIES, VehicleSizeSampler
from selfplaydrive.testing.spawn_reference import (
    aligned_candidates_reference,
    bimodal_uniform_reference,
    boxes_overlap_reference,
    greedy_separated_reference,
    pedestrian_batch_reference,
    pedestrian_paths_reference,
    place_agents_reference,
    place_statics_reference,
    roadside_poses_reference,
    sample_on_chunks_reference,
    vehicle_sizes_reference,
    waypoint_draws_reference,
)


@pytest.fixture(scope="module")
def scenarios_small(grid_map):
    sp = PaperSpawner(pedestrians=PedestrianSampler(count=(8, 8)))
    rng = np.random.default_rng(3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return [sp.sample(grid_map, rng) for _ in range(60)]


def test_cell_index_box_query_matches_brute_force():
    rng = np.random.default_rng(0)
    xy = rng.uniform(-300, 300, (5000, 2))
    cells = CellIndex.build(xy, 25.0)
    for _ in range(20):
        c = rng.uniform(-350, 350, 2)
        box = np.array([c[0] - 100, c[1] - 100, c[0] + 100, c[1] + 100])
        got = np.sort(cells.query_box(box))
        inside = (xy[:, 0] >= box[0]) & (xy[:, 0] <= box[2]) & (xy[:, 1] >= box[1]) & (xy[:, 1] <= box[3])
        np.testing.assert_array_equal(got, np.flatnonzero(inside))


def test_roadside_on_straight_map(straight_map):
    idx = MapIndex.build(straight_map)
    # both lanes are rightmost; kerbs 1.75 m right of each centreline (straight_map fixture)
    assert set(idx.roadside.lane.tolist()) == {0, 1}
    np.testing.assert_allclose(idx.roadside.edge, 1.75, atol=1e-4)
    assert (idx.roadside.s1 - idx.roadside.s0).sum() == pytest.approx(400.0, rel=1e-5)
    assert idx.spawn.s1.max() <= 200.0 + 1e-4
    # the whole 200 m map fits in one region: at least the best centres are kept
    assert len(idx.centres) >= 1


def test_crossings_span_the_road(grid_map):
    idx = map_index(grid_map)
    length = np.hypot(*(idx.crossings.end - idx.crossings.start).T)
    np.testing.assert_allclose(length, 7.0, atol=1e-3)  # two 3.5 m lanes, kerb to kerb
    # crosswalks: 7 m across the road (2 lanes), 3 m wide -> half width 1.5 - 0.3
    cw_len = np.hypot(*(idx.crosswalks.end - idx.crosswalks.start).T)
    np.testing.assert_allclose(cw_len, 7.0, atol=1e-3)
    np.testing.assert_allclose(idx.crosswalks.half_width, 1.2, atol=1e-6)
    assert len(idx.crosswalks.start) == len(grid_map.crosswalks)


def test_region_centres_have_enough_lane(grid_map):
    idx = MapIndex.build(grid_map, min_region_lane_length=1000.0)
    assert np.all(idx.centre_lane_length >= 1000.0)
    small = MapIndex.build(grid_map, min_region_lane_length=1e9)  # none qualifies: best half kept
    assert len(small.centres) >= 1
    assert np.all(small.centre_lane_length >= 0.5 * small.centre_lane_length.max())


def test_map_index_is_cached(grid_map):
    assert map_index(grid_map) is map_index(grid_map)
    assert map_index(grid_map, region_stride=10.0) is not map_index(grid_map)


def test_sample_on_chunks_kernel_matches_reference(grid_map):
    idx = map_index(grid_map)
    for seed in range(20):
        box = sample_region(idx, np.random.default_rng(seed))
        for chunks in (idx.spawn, idx.roadside):
            a = sample_on_chunks(idx, chunks, box, np.random.default_rng(seed), 200)
            b = sample_on_chunks_reference(idx, chunks, box, np.random.default_rng(seed), 200)
            for f in ("lane", "s", "xy", "heading", "chunk"):
                np.testing.assert_allclose(getattr(a, f), getattr(b, f), atol=1e-9, err_msg=f)
    empty = sample_on_chunks(
        idx, idx.spawn, np.array([1e5, 1e5, 1e5 + 1, 1e5 + 1]), np.random.default_rng(0), 50
    )
    assert len(empty.lane) == 0


def test_greedy_kernel_matches_reference_and_keeps_spacing():
    rng = np.random.default_rng(0)
    for _ in range(10):
        xy = rng.uniform(0, 120, (400, 2))
        r = rng.uniform(1.0, 8.0, 400)
        fixed = rng.uniform(0, 120, (6, 2))
        fr = np.full(6, 3.0)
        a = greedy_separated(xy, r, 40, fixed, fr, gap=0.5)
        b = greedy_separated_reference(xy, r, 40, fixed, fr, gap=0.5)
        np.testing.assert_array_equal(a, b)
        d = np.hypot(*(xy[a][:, None] - xy[a][None]).transpose(2, 0, 1))
        lim = r[a][:, None] + r[a][None] + 0.5
        np.fill_diagonal(d, np.inf)
        assert np.all(d >= lim)
    assert len(greedy_separated(xy, r, 0)) == 0


def test_roadside_offset_hand_computed():
    # kerb 1.75 m from the centreline, 0.3 m gap, car 1.8 m wide: centre 0.55 m right of centre
    off = roadside_offset(
        np.array([3.5, 3.5, 3.5]), np.array([1.75, 4.0, 1.75]), np.array([1.8, 1.8, 3.4]), 0.3, 1.0
    )
    # shoulder: right side at most 1.75 + 1.0 -> 2.75 - 0.9; a very wide vehicle never goes left of centre
    np.testing.assert_allclose(off, [0.55, 1.85, 0.0])


def test_vehicle_size_mix():
    s = VehicleSizeSampler()
    length, width, cat = s.sample(np.random.default_rng(0), 200_000)
    shares = np.bincount(cat, minlength=len(DEFAULT_CATEGORIES)) / len(cat)
    np.testing.assert_allclose(shares, [c[3] for c in DEFAULT_CATEGORIES], atol=0.005)
    assert length.min() >= 1.8 * 0.95 - 1e-9 and length.max() <= 12.0 * 1.05 + 1e-9
    assert width.min() >= 0.6 * 0.95 - 1e-9 and width.max() <= 2.55 + 1e-9
    bikes = cat == 0
    assert length[bikes].mean() == pytest.approx(1.8, rel=0.01) and width[bikes].mean() == pytest.approx(
        0.6, rel=0.01
    )
    with pytest.raises(ConfigError, match="each vehicle category"):
        VehicleSizeSampler(categories=[("car", 4.5, -1.0, 1.0)])
    with pytest.raises(ConfigError, match="jitter"):
        VehicleSizeSampler(jitter=0.9)


def test_light_sampler():
    s = LightSampler()
    rng = np.random.default_rng(0)
    draws = [s.sample(rng, 5, 30.0) for _ in range(4000)]
    assert np.mean([d[0] for d in draws]) == pytest.approx(0.5, abs=0.03)
    on = np.concatenate([d[1] for d in draws if d[0]])
    np.testing.assert_allclose(np.bincount(on, minlength=4) / len(on), 0.25, atol=0.02)
    off = [d for d in draws if not d[0]]
    assert all(np.all(d[1] == 0) and np.all(d[2] == 30.0) for d in off)
    assert LightSampler(all_off_prob=0.0).sample(rng, 0, 20.0)[1].shape == (0,)
    with pytest.raises(ConfigError, match="state_probs"):
        LightSampler(state_probs=(0.5, 0.5))
    with pytest.raises(ConfigError, match="time_left"):
        LightSampler(time_left=(0.0, 10.0))


def test_pedestrians_keep_clear_of_vehicles(grid_map):
    idx = map_index(grid_map)
    sampler = PedestrianSampler(count=(8, 8), crosswalk_share=1.0)
    box = np.array([-100.0, -100.0, 100.0, 100.0])
    peds = sampler.sample(
        np.random.default_rng(0), idx.crossings, idx.crosswalks, box, 8, np.zeros((0, 2)), np.zeros(0)
    )
    assert peds.valid.sum() == 8
    # every crossing starts at a crosswalk: its middle point lies on a crosswalk axis
    mids = (peds.path[:, 1] + peds.path[:, 2]) / 2
    cw_mid = (idx.crosswalks.start + idx.crosswalks.end) / 2
    assert np.all(np.min(np.hypot(*(mids[:, None] - cw_mid[None]).transpose(2, 0, 1)), axis=1) <= 1.2 + 1e-3)
    # a vehicle parked on every start point removes those pedestrians
    blocked = sampler.sample(
        np.random.default_rng(0),
        idx.crossings,
        idx.crosswalks,
        box,
        8,
        peds.path[:, 0].astype(np.float64),
        np.full(8, 2.0),
    )
    assert blocked.valid.sum() == 0
    with pytest.raises(ConfigError, match="speed"):
        PedestrianSampler(speed=(0.0, 1.0))


def test_no_roadside_spots_near_crosswalks_or_junction_mouths(grid_map):
    idx = map_index(grid_map)
    t = idx.routes
    lanes = grid_map.lanes
    for end in ("s0", "s1"):
        s = getattr(idx.roadside, end)
        xy, _ = t.points(idx.roadside.lane, s)
        cw_mid = (idx.crosswalks.start + idx.crosswalks.end) / 2
        d = np.min(np.hypot(*(xy[:, None] - cw_mid[None]).transpose(2, 0, 1)), axis=1)
        assert d.min() >= 5.0 + 1.5 - 1e-6  # 5 m clearance from a 3 m wide crosswalk
    # every grid road lane starts and ends at a junction or the map border: 5 m kept free
    at_junction_end = np.array([any(lanes.in_junction[lanes.successors(int(i))]) for i in idx.roadside.lane])
    room = t.length[idx.roadside.lane] - idx.roadside.s1
    assert np.all(room[at_junction_end] >= 5.0 - 1e-6)


def test_pedestrian_kernel_matches_reference(grid_map):
    """Site choice, paths and clearance tests of the kernel equal the NumPy reference bit for
    bit, on random draws with vehicles that block some paths (moving and standing)."""
    from selfplaydrive._sim.pedestrians import pedestrian_paths, pedestrian_sites

    idx = map_index(grid_map)
    rng = np.random.default_rng(8)
    blocked = total = 0
    for trial in range(40):
        box = np.array([-100.0, -100.0, 100.0, 100.0]) + rng.uniform(-60, 60, 2).repeat(2)
        n_cw, n_other, cw, other = pedestrian_sites(idx.crosswalks.kernel, idx.crossings.kernel, box)
        if n_cw + n_other == 0:
            continue
        u = rng.random((8, 9))
        share = (0.5 if trial % 2 else 1.0) if n_other else 1.0
        vxy = rng.uniform(-100, 100, (30, 2))
        r = rng.uniform(1.0, 8.0, 30)
        still = rng.random(30) < 0.5
        path, ok = np.empty((8, 3, 2)), np.empty(8, dtype=bool)
        pedestrian_paths(idx.crosswalks.kernel, idx.crossings.kernel, cw, other, u, share, 1.0, 5.0,
                         vxy, r, still, path, ok)  # fmt: skip
        want_path, want_ok = pedestrian_paths_reference(
            idx.crosswalks, idx.crossings, box, u, share, 1.0, 5.0, vxy, r, still
        )
        np.testing.assert_array_equal(path, want_path)
        np.testing.assert_array_equal(ok, want_ok)
        blocked += int((~ok).sum())
        total += len(ok)
    assert total > 100 and 0 < blocked < total  # the clearance tests decided some


def test_placement_kernels_match_references(grid_map):
    """Vehicle sizes, aligned candidates, roadside poses and the bimodal coefficient draw of
    the spawner kernels equal their NumPy references bit for bit on random inputs (headings
    around the +-pi wrap, lanes narrower than vehicles, edges missing)."""
    from selfplaydrive._sim.placement import aligned_candidates, roadside_poses
    from selfplaydrive._sim.samplers import bimodal_uniform, vehicle_sizes

    idx = map_index(grid_map)
    lanes = grid_map.lanes
    rng = np.random.default_rng(9)
    sizes = VehicleSizeSampler()
    for n in (0, 1, 7, 300):
        u = rng.random((3, n))
        got = vehicle_sizes(u, sizes._cdf, sizes.length, sizes.width, sizes.jitter, sizes.max_width)
        want = vehicle_sizes_reference(
            u, sizes._cdf, sizes.length, sizes.width, sizes.jitter, sizes.max_width
        )
        for g, w in zip(got, want, strict=True):
            np.testing.assert_array_equal(g, w)
        length, width, _ = got
        lane = rng.integers(0, len(lanes.width), n)
        s = rng.uniform(0, 50, n)
        xy = rng.uniform(-100, 100, (n, 2))
        heading = rng.uniform(-np.pi, np.pi, n)
        heading[: n // 3] = np.pi - rng.uniform(0, 1e-3, n // 3)  # noise crosses the wrap
        u = rng.random((3, n))
        out = np.empty((n, 10))
        aligned_candidates(lane, s, xy, heading, np.sin(heading), np.cos(heading), length, width, u,
                           lanes.width, lanes.speed_limit, 0.25, 0.05, 0.0, 5.0, out)  # fmt: skip
        want = aligned_candidates_reference(
            lane, s, xy, heading, length, width, u, lanes.width, lanes.speed_limit, 0.25, 0.05, (0.0, 5.0)
        )
        np.testing.assert_array_equal(out, want)
        chunk = rng.integers(0, len(idx.roadside.edge), n)
        edge = idx.roadside.edge.copy()
        edge[rng.random(len(edge)) < 0.2] = np.inf
        got = (np.empty((n, 2)), np.empty(n), np.empty(n, dtype=bool))
        roadside_poses(lane, chunk, xy, np.sin(heading), np.cos(heading), width, lanes.width, edge,
                       0.3, 1.0, 1.0, *got)  # fmt: skip
        want = roadside_poses_reference(lane, chunk, xy, heading, width, lanes.width, edge, 0.3, 1.0, 1.0)
        for g, w in zip(got, want, strict=True):
            np.testing.assert_array_equal(g, w)
        u = rng.random((n, 10))
        lo, hi = rng.uniform(0, 1, 8), rng.uniform(1, 2, 8)
        np.testing.assert_array_equal(
            bimodal_uniform(u, lo, hi, 5, 0.0, 0.1, 0.5, 7, 0.0, 0.2, 0.3),
            bimodal_uniform_reference(u, lo, hi, 5, (0.0, 0.1), 0.5, 7, (0.0, 0.2), 0.3),
        )


def test_pedestrian_paths_avoid_stationary_vehicles(grid_map):
    idx = map_index(grid_map)
    sampler = PedestrianSampler(count=(8, 8), crosswalk_share=0.0)
    box = np.array([-100.0, -100.0, 100.0, 100.0])
    free = sampler.sample(
        np.random.default_rng(1), idx.crossings, idx.crosswalks, box, 8, np.zeros((0, 2)), np.zeros(0)
    )
    assert free.valid.sum() == 8
    # a vehicle in the middle of each crossing: stationary blocks the path, moving does not
    mid = ((free.path[:, 1] + free.path[:, 2]) / 2).astype(np.float64)
    args = (idx.crossings, idx.crosswalks, box, 8, mid, np.full(8, 1.0))
    moving = sampler.sample(np.random.default_rng(1), *args, np.zeros(8, dtype=bool))
    assert moving.valid.sum() == 8
    still = sampler.sample(np.random.default_rng(1), *args, np.ones(8, dtype=bool))
    assert still.valid.sum() == 0


def test_scenario_pedestrians_never_walk_through_parked_or_static(scenarios_small):
    for s in scenarios_small:
        still_xy = np.concatenate([s.agent_xy[s.agent_parked], s.static_xy[s.static_valid]]).astype(
            np.float64
        )
        still_r = np.concatenate(
            [
                0.5 * np.hypot(s.agent_length, s.agent_width)[s.agent_parked],
                0.5 * np.hypot(s.static_length, s.static_width)[s.static_valid],
            ]
        )
        for p in s.ped_path[s.ped_valid].astype(np.float64):
            for a, b in ((p[0], p[1]), (p[1], p[2])):
                d = b - a
                t = np.clip(((still_xy - a) @ d) / max(d @ d, 1e-12), 0, 1)
                dist = np.hypot(*(still_xy - (a + t[:, None] * d)).T)
                assert np.all(dist >= still_r + 1.0 - 1e-3)


@pytest.mark.parametrize(
    "kwargs",
    [
        {},
        # many parked agents far apart: parked shortfalls and a second aligned round
        {"parked_share": 0.6, "min_agent_distance": 30.0},
        # a tiny candidate budget: shortfalls; every static slot wanted, little static gap
        {"first_round_candidates": 1, "candidates_per_agent": 3, "static_count": (48, 48), "static_gap": 0.2},
    ],
)
def test_placement_kernel_matches_reference(grid_map, kwargs):
    """`Placer.agents` and `Placer.statics` equal their NumPy references bit for bit over random
    regions: the same draws from the same generator (checked by the next draw of each), the same
    candidates accepted, the same slots."""
    sp = PaperSpawner(**kwargs)
    idx = sp.prepare(grid_map)
    k = idx.kernels
    placed = parked_total = statics_total = short = 0
    for seed in range(10):
        box = sample_region(idx, np.random.default_rng(100 + seed))
        n_parked = int(np.random.default_rng(seed).binomial(sp.num_agents, sp.parked_share))
        sc = Scenario.empty(sp.num_agents, sp.max_waypoints, sp.num_static, 0, PATH_POINTS, 0)
        rng_k, rng_r = np.random.default_rng(seed), np.random.default_rng(seed)
        got, parked, lane, s = sp._placer.agents(k.spawn, k.roadside, rng_k, box, sp.num_agents, n_parked, sc)
        rows, parked_ref = place_agents_reference(sp, idx, box, rng_r, n_parked)
        assert (got, parked) == (len(rows), parked_ref)
        np.testing.assert_array_equal(lane, rows[:, 0].astype(np.int64))
        np.testing.assert_array_equal(s, rows[:, 1])
        for name, col in (("xy", slice(2, 4)), ("heading", 4), ("speed", 5), ("length", 6), ("width", 7)):
            np.testing.assert_array_equal(getattr(sc, f"agent_{name}")[:got], rows[:, col].astype(np.float32))
        np.testing.assert_array_equal(sc.agent_parked[:got], rows[:, 8] != 0)
        np.testing.assert_array_equal(sc.agent_lane[:got], np.where(rows[:, 9] != 0, rows[:, 0], -1))
        assert not sc.agent_valid[got:].any() and sc.agent_valid[:got].all()
        assert rng_k.random() == rng_r.random()
        want = int(np.random.default_rng(seed).integers(sp.static_count[0], sp.static_count[1] + 1))
        m, vxy, vr, still = sp._placer.statics(k.roadside, rng_k, box, want, got, sc)
        agents = {f: getattr(sc, f"agent_{f}")[:got] for f in ("xy", "heading", "speed", "length", "width")}
        ref = place_statics_reference(sp, idx, box, rng_r, want, agents, STATIC_CLEAR_AHEAD, STATIC_HEADWAY)
        assert m == len(ref) and sc.static_valid[:m].all() and not sc.static_valid[m:].any()
        for name, col in (("xy", slice(0, 2)), ("heading", 2), ("length", 3), ("width", 4)):
            np.testing.assert_array_equal(getattr(sc, f"static_{name}")[:m], ref[:, col].astype(np.float32))
        assert rng_k.random() == rng_r.random()
        # every vehicle for the pedestrians: agents then statics, as stored
        xy = np.concatenate([sc.agent_xy[:got], sc.static_xy[:m]]).astype(np.float64)
        length = np.concatenate([sc.agent_length[:got], sc.static_length[:m]]).astype(np.float64)
        width = np.concatenate([sc.agent_width[:got], sc.static_width[:m]]).astype(np.float64)
        np.testing.assert_array_equal(vxy, xy)
        np.testing.assert_array_equal(vr, 0.5 * np.hypot(length, width))
        np.testing.assert_array_equal(still, np.concatenate([sc.agent_parked[:got], np.ones(m, dtype=bool)]))
        placed += got
        parked_total += parked
        statics_total += m
        short += got < sp.num_agents
    assert placed > 0 and parked_total > 0 and statics_total > 0
    if kwargs:
        assert short > 0  # the shortfall paths ran


def test_boxes_meet_kernel_matches_reference():
    """The separating-axis test of the static placement agrees with the corner-projection
    reference on random box pairs, overlapping and apart."""
    from selfplaydrive._sim.placement import boxes_meet

    rng = np.random.default_rng(4)
    hits = 0
    for _ in range(3000):
        a = np.array([*rng.uniform(-5, 5, 2), rng.uniform(-np.pi, np.pi), *rng.uniform(0.3, 6.0, 2)])
        b = np.array([*rng.uniform(-5, 5, 2), rng.uniform(-np.pi, np.pi), *rng.uniform(0.3, 6.0, 2)])
        got = boxes_meet(a[0], a[1], a[2], 2 * a[3], 2 * a[4], b[0], b[1], b[2], 2 * b[3], 2 * b[4])
        assert got == boxes_overlap_reference(a, b)
        hits += got
    assert 300 < hits < 2700


def test_waypoint_draws_match_numpy_calls(grid_map):
    """`RouteKernel.draw_waypoints` draws what `waypoint_times` and `rng.integers(0, 2**63)`
    draw (same values, same stream position), so its waypoints equal `waypoints` fed with
    those."""
    idx = map_index(grid_map)
    lane = idx.spawn.lane[::7][:20].copy()
    s = np.linspace(0.0, 3.0, len(lane))
    for seed in range(5):
        a, ca = np.zeros((len(lane), 8, 2), np.float32), np.zeros(len(lane), np.int32)
        b, cb = np.zeros_like(a), np.zeros_like(ca)
        rng_k, rng_r = np.random.default_rng(seed), np.random.default_rng(seed)
        idx.kernels.routes.draw_waypoints(rng_k, lane, s, 8, 5.0, 0.5, 0.3, MIN_CHANGE_LENGTH, 128, a, ca)
        times, key = waypoint_draws_reference(rng_r, len(lane), 8, 5.0, 0.5)
        idx.kernels.routes.waypoints(lane, s, times, key, 0.3, MIN_CHANGE_LENGTH, 128, b, cb)
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(ca, cb)
        assert rng_k.random() == rng_r.random()
        assert ca.min() >= 1


def test_pedestrian_sampler_matches_reference(grid_map):
    """`PedestrianSampler.sample` (kernel `pedestrian_batch`) equals the NumPy reference field by
    field, with vehicles that block some pedestrians, and leaves the generator where it does."""
    idx = map_index(grid_map)
    sampler = PedestrianSampler(count=(2, 8))
    rng = np.random.default_rng(12)
    kept = 0
    for seed in range(40):
        box = np.array([-100.0, -100.0, 100.0, 100.0]) + rng.uniform(-60, 60, 2).repeat(2)
        vxy = rng.uniform(-100, 100, (30, 2))
        vr = rng.uniform(1.0, 6.0, 30)
        still = rng.random(30) < 0.5
        rng_k, rng_r = np.random.default_rng(seed), np.random.default_rng(seed)
        a = sampler.sample(rng_k, idx.crossings, idx.crosswalks, box, 8, vxy, vr, still)
        b = pedestrian_batch_reference(sampler, rng_r, idx.crossings, idx.crosswalks, box, 8, vxy, vr, still)
        for f in ("valid", "path", "num_points", "speed", "start_time", "size"):
            np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)
        assert rng_k.random() == rng_r.random()
        kept += int(a.valid.sum())
    assert 0 < kept < 40 * 8
