"""The traffic-rule encoder `obs=rules` (issue #15 item 1, observation part): hand-computed rows
(a STOP line vs a YIELD line; a crosswalk with a pedestrian on it, empty, a pedestrian walking
towards it or away), the kernel's crosswalk test against obs/rule_features.py on random
polygons, the env's rows against the NumPy reference on random scenes (1 and 2 threads), the
shipped encoder checker, and the bind step."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from rules_scenes import CW_EAST, STOP_MID, YIELD_MID, SceneSpawner, rules_map

from selfplaydrive._sim import obs_rules as kernel
from selfplaydrive.errors import ConfigError
from selfplaydrive.maps.loader import load_map
from selfplaydrive.obs import PaperEncoder, RulesEncoder, bind_encoder
from selfplaydrive.obs import rule_features as rf
from selfplaydrive.obs.rules import pack
from selfplaydrive.scenario.spawner import PaperSpawner
from selfplaydrive.sim import VecEnv
from selfplaydrive.sim.atlas import build_atlas
from selfplaydrive.sim.params import SimParams
from selfplaydrive.testing import rules_reference as ref
from selfplaydrive.testing.check_encoder import check_encoder

EGO, OBJ, ROAD = 19, 9, 8
POS = 100.0  # position scale (the radius)


@pytest.fixture(scope="module")
def road():
    return rules_map()


def first_road_rows(road_map, peds=()):
    """The road rows (n, 8) of the single agent (at (0, -1.75), heading east) after reset."""
    env = VecEnv(road_map, SceneSpawner(peds), 1, obs=RulesEncoder())
    obs = env.reset(0)[0]
    return obs[EGO + 63 * OBJ :].reshape(200, ROAD)[: env.state.road_n[0]]


def row_at(rows, x, y):
    """The row of the segment whose midpoint is (x, y) [m] (the agent is at (0, -1.75))."""
    dx, dy = np.float32(x / POS), np.float32((y + 1.75) / POS)
    hit = np.flatnonzero((np.abs(rows[:, 1] - dx) < 1e-6) & (np.abs(rows[:, 2] - dy) < 1e-6))
    assert len(hit) == 1, f"no single row at ({x}, {y})"
    return rows[hit[0]]


def crosswalk_states(rows):
    """State column of the crosswalk rows (type 1) east (dx > 0) and west of the agent."""
    walk = rows[rows[:, 6] == 1.0]
    return walk[walk[:, 1] > 0, 7], walk[walk[:, 1] < 0, 7]


# --- hand-computed rows --------------------------------------------------------------------------
def test_a_stop_line_row_differs_from_a_yield_line_row_only_in_its_type(road):
    rows = first_road_rows(road)
    stop, yld = row_at(rows, *STOP_MID), row_at(rows, *YIELD_MID)
    # STOP line: midpoint (20, -1.75), 20 m ahead; across the lane (direction +y), 3.5 m long
    np.testing.assert_allclose(stop, [1, 0.2, 0.0, 0.0, 1.0, 3.5 / 20, 0.625, 0], rtol=0, atol=1e-6)
    # YIELD line: midpoint (-20, 1.75), 20 m behind and 3.5 m left; the paper's stop-line type 0.5
    np.testing.assert_allclose(yld, [1, -0.2, 0.035, 0.0, 1.0, 3.5 / 20, 0.5, 0], rtol=0, atol=1e-6)
    assert stop[6] == np.float32(0.625) and yld[6] == np.float32(0.5)  # exact: the type values
    paper = VecEnv(road, SceneSpawner(), 1, obs=PaperEncoder()).reset(0)[0]
    prow = paper[EGO + 63 * OBJ :].reshape(200, ROAD)
    assert (prow[:, 6] == 0.5).sum() == 2  # the paper: both lines 0.5


def test_an_empty_crosswalk_is_not_marked(road):
    east, west = crosswalk_states(first_road_rows(road))
    assert len(east) == 4 and len(west) == 4  # four sides each
    assert not east.any() and not west.any()


def test_a_pedestrian_on_the_crosswalk_marks_all_its_segments(road):
    on = dict(path=[(41.5, -2.0), (41.5, 2.0)], speed=1.2)  # inside x 40..43
    east, west = crosswalk_states(first_road_rows(road, [on]))
    np.testing.assert_array_equal(east, np.ones(4, np.float32))
    assert not west.any()


@pytest.mark.parametrize(
    ("x0", "x1", "marked"),
    [
        (44.9, 30.0, True),  # walking west at 1 m/s, 1.9 m off the edge: in 1.5 s 0.4 m off (< 0.5)
        (45.5, 30.0, False),  # in 1.5 s at 44.0, 1.0 m off the edge: not about to enter
        (44.0, 60.0, False),  # 1.0 m off the edge, walking away
        (43.4, 60.0, True),  # walking away, but still within 0.5 m of the outline
    ],
)
def test_a_pedestrian_walking_towards_the_crosswalk(road, x0, x1, marked):
    ped = dict(path=[(x0, 0.0), (x1, 0.0)], speed=1.0)
    east, west = crosswalk_states(first_road_rows(road, [ped]))
    np.testing.assert_array_equal(east, np.full(4, float(marked), np.float32))
    assert not west.any()


def test_a_standing_pedestrian_counts_by_position_only(road):
    waiting = dict(path=[(43.4, 0.0), (43.4, 1.0)], speed=1.0, start=50.0)  # not started: v = 0
    far = dict(path=[(-44.0, 0.0), (-44.0, 1.0)], speed=1.0, start=50.0)  # 1 m off the west one
    east, west = crosswalk_states(first_road_rows(road, [waiting, far]))
    assert east.all() and not west.any()


def test_the_rule_by_hand():
    poly = CW_EAST
    x = np.float32([41.0, 43.49, 43.51, 44.9, 45.5, 38.0])
    vx = np.float32([0.0, 0.0, 0.0, -1.0, -1.0, 2.0])
    y = np.zeros(6, np.float32)
    got = rf.pedestrians_on_crosswalk(poly, x, y, vx, y)
    np.testing.assert_array_equal(got, [True, True, False, True, False, True])


# --- kernel vs NumPy -----------------------------------------------------------------------------
def random_polygon(rng, centre):
    """A star-shaped polygon of 3 to 9 points (concave ones too) around `centre`."""
    k = int(rng.integers(3, 10))
    ang = np.sort(rng.uniform(0, 2 * np.pi, k))
    r = rng.uniform(0.5, 6.0, k)
    return (centre + np.stack([r * np.cos(ang), r * np.sin(ang)], axis=1)).astype(np.float32)


def test_kernel_occupancy_matches_numpy_on_random_polygons():
    rng = np.random.default_rng(7)
    polys = [random_polygon(rng, rng.uniform(-500, 500, 2)) for _ in range(60)]
    cw_pts = np.concatenate([[0], np.cumsum([len(p) for p in polys])]).astype(np.int32)
    box = np.array([[*(p.min(0) - 0.51), *(p.max(0) + 0.51)] for p in polys], np.float32)
    map_cw = np.int32([0, len(polys)])
    grids = rf.crosswalk_grids(box, map_cw, rf.GRID_CELL)
    pts = np.concatenate(polys)
    no_stops = rf.stop_tables(
        np.zeros(0, np.int32), np.int64([0, 0]), np.zeros((0, 2)), np.zeros(0, np.int32), 20.0
    )
    data = rf.RuleMapData(np.zeros(0, np.int32), map_cw, np.int32([0]), cw_pts, pts, box, *grids, *no_stops)
    args = pack(data)
    hits = 0
    for trial in range(300):
        c = int(rng.integers(len(polys)))
        poly = polys[c]
        n = int(rng.integers(0, 5))
        # points on the outline moved by up to 0.8 m (the 0.5 m margin is decided there), or
        # anywhere within 9 m of the centre
        e = rng.integers(len(poly), size=n)
        t = rng.uniform(0, 1, (n, 1))
        edge = poly[e] + t * (poly[(e + 1) % len(poly)] - poly[e]) + rng.uniform(-0.8, 0.8, (n, 2))
        anywhere = poly.mean(axis=0) + rng.uniform(-9, 9, (n, 2))
        xy = np.where(rng.random((n, 1)) < 0.5, edge, anywhere).astype(np.float32)
        vx, vy = (rng.uniform(-3, 3, (2, n)) * (rng.random(n) < 0.7)).astype(np.float32)
        x, y = np.ascontiguousarray(xy[:, 0]), np.ascontiguousarray(xy[:, 1])
        got = kernel.occupied_flags(args, 0, x, y, vx, vy)
        want = np.array([rf.pedestrians_on_crosswalk(p, x, y, vx, vy).any() for p in polys])
        np.testing.assert_array_equal(got, want, err_msg=f"trial {trial}")
        hits += int(want[c])
    assert 60 < hits < 240, hits  # both outcomes are exercised


def stop_town():
    """The bundled town with every other stop line made a STOP line (118 of its 304 are)."""
    town = load_map("default")
    kinds = np.zeros(len(town.stop_kind), np.int8)
    kinds[1::2] = 1
    return dataclasses.replace(town, stop_kind=kinds)


def many_pedestrians():
    return PaperSpawner(num_agents=12, num_static=4, num_pedestrians=8, episode_lengths=(3.0,))


class CrosswalkPedestrians:
    """The scenes of `spawner` with every pedestrian walking a random path around a random
    crosswalk of the map (within 6 m of its centre), so that crosswalks are often occupied."""

    def __init__(self, spawner) -> None:
        self.spawner = spawner

    def sample(self, road_map, rng, map_index: int = 0):
        sc = self.spawner.sample(road_map, rng, map_index=map_index)
        P, T = sc.ped_path.shape[:2]
        for k in range(P):
            centre = road_map.crosswalks[int(rng.integers(len(road_map.crosswalks)))].mean(axis=0)
            sc.ped_path[k] = centre + rng.uniform(-6.0, 6.0, (T, 2))
        sc.ped_valid[:] = True
        sc.ped_size[:] = (0.5, 0.5)
        sc.ped_num_points[:] = T
        sc.ped_speed[:] = rng.uniform(0.5, 2.0, P)
        sc.ped_start_time[:] = rng.uniform(0.0, 1.0, P)
        return sc


@pytest.mark.parametrize(
    ("threads", "cand_cap"),
    [(1, 8192), (2, 8192), (1, 538)],
    ids=["1-thread", "2-threads", "small-scratch"],
)
def test_env_rows_match_the_reference_on_random_scenes(threads, cand_cap):
    """cand_cap=538: the scratch holds the crosswalk flags of this town (538) and nothing more,
    so the kernel takes its other path (flags after the paper encoder); the paper env has the
    same scratch (the road gather depends on it)."""
    town = stop_town()
    envs = [
        VecEnv(
            town,
            CrosswalkPedestrians(many_pedestrians()),
            3,
            obs=enc,
            seed=5,
            num_threads=threads,
            params=SimParams(cand_cap=cand_cap),
        )
        for enc in (PaperEncoder(), RulesEncoder())
    ]
    assert envs[0].dims.cand_cap == envs[1].dims.cand_cap == max(cand_cap, len(town.crosswalks))
    rng = np.random.default_rng(3)
    for e in envs:
        e.reset(5)
    marks = {"stop": 0, "busy": 0}
    for step in range(45):  # resets at 3 s
        paper, rules = envs[0].observations, envs[1].observations
        want = ref.encode(paper, envs[1].state, envs[1].maps, envs[1].atlas, 63, 200)
        act = envs[1].masks
        np.testing.assert_array_equal(rules[act], want[act], err_msg=f"step {step}")
        road = rules[act, EGO + 63 * OBJ :].reshape(-1, 200, ROAD)
        marks["stop"] += int((road[..., 6] == np.float32(rf.STOP_LINE_TYPE)).sum())
        marks["busy"] += int(((road[..., 6] == 1.0) & (road[..., 7] == 1.0)).sum())
        a = rng.integers(0, envs[0].action_space.nvec, size=(envs[0].num_agents, 2))
        for e in envs:
            e.step(a)
    assert marks["stop"] > 100 and marks["busy"] > 30, marks  # both features occur


def test_rollout_is_the_same_at_1_and_2_threads():
    town = stop_town()
    spawner = CrosswalkPedestrians(many_pedestrians())
    envs = [VecEnv(town, spawner, 4, obs=RulesEncoder(), seed=2, num_threads=t) for t in (1, 2)]
    for e in envs:
        e.reset(2)
    rng = np.random.default_rng(0)
    for _ in range(30):
        a = rng.integers(0, envs[0].action_space.nvec, size=(envs[0].num_agents, 2))
        for e in envs:
            e.step(a)
        np.testing.assert_array_equal(envs[0].observations, envs[1].observations)
        np.testing.assert_array_equal(envs[0].final_observations, envs[1].final_observations)


def test_the_shipped_checker_passes():
    report = check_encoder(RulesEncoder(), stop_town(), spawner=many_pedestrians())
    assert report.rows_checked > 0 and report.isolation_checks > 0 and report.max_abs <= 1.0


def test_a_map_without_stop_lines_or_crosswalks_gives_the_paper_rows(straight_map):
    spawner = SceneSpawner()
    envs = [VecEnv(straight_map, spawner, 2, obs=enc, seed=1) for enc in (PaperEncoder(), RulesEncoder())]
    assert envs[1].encoder.scratch == 0
    for e in envs:
        e.reset(1)
    for _ in range(5):
        for e in envs:
            e.step(np.full((e.num_agents, 2), (3, 6)))
        np.testing.assert_array_equal(envs[0].observations, envs[1].observations)


# --- binding -------------------------------------------------------------------------------------
def test_the_env_binds_the_encoder_to_its_maps(road):
    enc = RulesEncoder()
    assert not enc.bound and enc.args is None
    env = VecEnv(road, SceneSpawner(), 1, obs=enc)
    assert env.encoder.bound and env.encoder.layout == enc.layout and isinstance(env.encoder, RulesEncoder)
    assert env.encoder.scratch == 2  # one flag per crosswalk of the map
    assert not enc.bound  # the configured encoder is left as it was


def test_binding_to_an_atlas_of_other_maps_is_refused(road):
    with pytest.raises(ValueError, match=r"atlas: .* segments, the maps have"):
        RulesEncoder().bind([road], build_atlas([road, road]))


def test_a_bind_that_changes_the_layout_is_a_config_error(road):
    class Shrinks(RulesEncoder):
        def bind(self, maps, atlas):
            return RulesEncoder(max_objects=8)

    with pytest.raises(ConfigError, match="bind\\(maps, atlas\\) must return an encoder of the same"):
        bind_encoder(Shrinks(), [road], build_atlas([road]))


def test_an_encoder_without_bind_is_used_as_is(road):
    enc = PaperEncoder()
    assert bind_encoder(enc, [road], build_atlas([road])) is enc


def test_the_config_group_builds_it():
    from hydra.utils import instantiate

    from selfplaydrive.builder import compose

    enc = instantiate(compose("sim", ["obs=rules", "obs.max_road=64"]).obs)
    assert isinstance(enc, RulesEncoder) and enc.layout == PaperEncoder(max_road=64).layout
    with pytest.raises(ConfigError):
        RulesEncoder(max_road=0)
