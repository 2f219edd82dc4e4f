"""Kernels against the NumPy references (selfplaydrive/testing/reference.py) on random states."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import RandomSpawner, cross_map

from selfplaydrive.physics import BicycleModel, FrictionBicycleModel
from selfplaydrive.rewards import TERM_NAMES
from selfplaydrive.scenario.types import COEFF_NAMES
from selfplaydrive.sim import VecEnv
from selfplaydrive.sim.params import COEFF_SCALE, SimParams
from selfplaydrive.testing import reference as ref


@pytest.fixture(scope="module")
def cmap():
    return cross_map()


def random_env(cmap, physics, seed, **kw):
    env = VecEnv(cmap, RandomSpawner(), 6, physics=physics, seed=seed, **kw)
    env.reset(seed)
    return env


@pytest.mark.parametrize("friction", [False, True])
def test_physics_matches_reference(cmap, friction):
    env = random_env(cmap, FrictionBicycleModel() if friction else BicycleModel(), 3)
    rng = np.random.default_rng(0)
    b = env.buffers
    for _ in range(5):
        acts = rng.integers(0, [7, 13], size=(env.num_agents, 2))
        pre = {k: b[k].copy() for k in ("x", "y", "heading", "speed", "length", "hidden", "active")}
        env.step(acts)
        moved = pre["active"].astype(bool) & (b["step"] > 0).repeat(env.dims.A)  # reset worlds have step 0
        want = ref.bicycle_step(
            pre["x"],
            pre["y"],
            pre["heading"],
            pre["speed"],
            pre["length"],
            env.action_table.accel[acts[:, 0]],
            env.action_table.steer[acts[:, 1]],
            pre["hidden"].astype(np.float64),
            friction=friction,
        )
        for k in ("x", "y", "speed", "a_long", "a_lat"):
            np.testing.assert_allclose(b[k][moved], want[k][moved], rtol=2e-4, atol=2e-3, err_msg=k)
        dh = np.angle(np.exp(1j * (b["heading"][moved] - want["heading"][moved])))
        assert np.all(np.abs(dh) < 1e-4)


def test_collisions_match_reference(cmap):
    rng = np.random.default_rng(1)
    env = VecEnv(cmap, RandomSpawner(A=16, S=8, P=0), 4, physics=BicycleModel(), seed=5)
    b = env.buffers
    checked = 0
    for trial in range(5):
        env.reset(trial)
        # freeze: zero speed and zero action, so the end-of-step boxes are the boxes
        b["speed"][:] = 0.0
        b["x"][:] = b["x"] * 0.3  # crowd them to get overlaps
        b["px"][:] = b["x"]
        b["y"][:] = b["y"] * 0.3
        b["py"][:] = b["y"]
        env.step(np.tile(np.array([3, 6]), (env.num_agents, 1)))
        for w in range(env.num_worlds):
            if b["step"][w] == 0:
                continue
            for a in range(env.dims.A):
                i = w * env.dims.A + a
                if not env.reward_mask[i]:
                    continue
                box = ref.box_corners(b["x"][i], b["y"][i], b["heading"][i], b["length"][i], b["width"][i])
                hit = any(
                    ref.boxes_overlap(
                        box,
                        ref.box_corners(b["x"][j], b["y"][j], b["heading"][j], b["length"][j], b["width"][j]),
                    )
                    for j in range(w * env.dims.A, (w + 1) * env.dims.A)
                    if j != i and env.reward_mask[j]
                )
                hit |= any(
                    ref.boxes_overlap(
                        box,
                        ref.box_corners(
                            b["st_x"][k],
                            b["st_y"][k],
                            math.atan2(b["st_sin"][k], b["st_cos"][k]),
                            b["st_len"][k],
                            b["st_wid"][k],
                        ),
                    )
                    for k in range(w * env.dims.S, (w + 1) * env.dims.S)
                    if b["st_valid"][k]
                )
                assert bool(b["events"][i] & 1) == hit, (w, a)
                checked += 1
    assert checked > 50
    del rng


# the reward group's constants away from the paper's (reward.*: docs/rewards.md)
OTHER_REWARD = SimParams(
    waypoint_reward=0.7, velocity_reward=0.01, velocity_min=1.0, center_max_angle_deg=30.0,
    collision_speed_gain=0.3, center_bonus=0.2, center_bonus_offset=1.0, align_bonus=0.01,
)  # fmt: skip


@pytest.mark.parametrize("params", [None, OTHER_REWARD], ids=["paper", "other"])
def test_lane_association_offroad_and_rewards_match_reference(cmap, params):
    env = random_env(cmap, FrictionBicycleModel(), 11, params=params)
    rng = np.random.default_rng(2)
    b = env.buffers
    names = list(COEFF_NAMES)
    n = 0
    for _ in range(15):
        env.step(rng.integers(0, [7, 13], size=(env.num_agents, 2)))
        for i in np.flatnonzero(env.reward_mask):
            if b["step"][i // env.dims.A] == 0:
                continue
            lane = ref.lane_association(cmap, float(b["x"][i]), float(b["y"][i]), float(b["heading"][i]))
            assert bool(b["lane_valid"][i]) == lane[0]
            if lane[0]:
                assert b["lane_s"][i] == pytest.approx(lane[1], abs=1e-3)
                assert b["lane_alpha"][i] == pytest.approx(lane[2], abs=1e-4)
            box = ref.box_corners(b["x"][i], b["y"][i], b["heading"][i], b["length"][i], b["width"][i])
            seg = cmap.segments
            near = np.flatnonzero((seg.type == 1) & (np.hypot(*(seg.mid - (b["x"][i], b["y"][i])).T) < 25.0))
            off = any(ref.segment_touches_box(seg.start[k], seg.end[k], box) for k in near)
            ev = int(b["events"][i])
            assert bool(ev & 4) == off
            events = dict(
                waypoint=ev & 16, collision=ev & 3, offroad=ev & 4, red_light=ev & 8, comfort=ev & 32
            )
            coeffs = dict(zip(names, b["coeffs"][i].astype(np.float64), strict=True))
            lane_k = (bool(b["lane_valid"][i]), float(b["lane_s"][i]), float(b["lane_alpha"][i]))
            want = ref.reward_terms(events, float(b["speed"][i]), coeffs, lane_k, params)
            np.testing.assert_allclose(
                env.reward_terms[i], want, rtol=1e-4, atol=1e-7, err_msg=str(TERM_NAMES)
            )
            n += 1
    assert n > 30


def _sorted_rows(rows: np.ndarray) -> np.ndarray:
    return rows[np.lexsort(rows.T[::-1])] if len(rows) else rows


def test_observation_matches_reference(cmap):
    env = random_env(cmap, FrictionBicycleModel(), 21)
    rng = np.random.default_rng(3)
    b, L = env.buffers, env.layout
    for _ in range(6):
        env.step(rng.integers(0, [7, 13], size=(env.num_agents, 2)))
    obs = env.layout.split(env.observations)
    assert np.all(np.isfinite(env.observations)) and np.all(np.abs(env.observations) <= 1.0)
    n = 0
    for i in np.flatnonzero(env.masks):
        w = i // env.dims.A
        np.testing.assert_allclose(obs["ego"][i], ref.ego_row(b, env.dims, i, COEFF_SCALE), atol=2e-5)
        objs = ref.object_rows(b, env.dims, i)
        got = obs["objects"][i]
        assert int(got[:, 0].sum()) == min(len(objs), L.max_objects)
        np.testing.assert_allclose(
            _sorted_rows(got[got[:, 0] > 0]),
            _sorted_rows(objs)[: L.max_objects]
            if len(objs) <= L.max_objects
            else _sorted_rows(got[got[:, 0] > 0]),
            atol=2e-5,
        )
        assert np.all(got[got[:, 0] == 0] == 0.0)
        road = ref.road_rows(
            cmap,
            b["light_state"][w * env.dims.G : (w + 1) * env.dims.G],
            float(b["x"][i]),
            float(b["y"][i]),
            float(b["heading"][i]),
        )
        gr = obs["road"][i]
        assert int(gr[:, 0].sum()) == len(road)
        np.testing.assert_allclose(_sorted_rows(gr[gr[:, 0] > 0]), _sorted_rows(road), atol=2e-5)
        assert np.all(gr[gr[:, 0] == 0] == 0.0)
        n += 1
    assert n > 5


@pytest.mark.parametrize("max_objects, max_road, radius", [(3, 12, 100.0), (5, 40, 30.0)])
def test_nearest_selection_matches_reference_when_it_binds(cmap, max_objects, max_road, radius):
    """Few observed slots, so the partial selections (road shells with the distance bound of
    the previous step, object quickselect) decide which rows appear, over 25 steps."""
    from selfplaydrive.obs.config import ObsConfig

    env = random_env(cmap, FrictionBicycleModel(), 5, obs=ObsConfig(max_objects, max_road, radius))
    rng = np.random.default_rng(4)
    b, L = env.buffers, env.layout
    bound = 0
    for _ in range(25):
        env.step(rng.integers(0, [7, 13], size=(env.num_agents, 2)))
        obs = L.split(env.observations)
        ended = (env.terminations | env.truncations).reshape(env.num_worlds, -1).any(axis=1)
        for i in np.flatnonzero(env.masks):
            w = i // env.dims.A
            if ended[w]:
                continue  # agents that ended this step were still observed in it
            road = ref.road_rows(
                cmap,
                b["light_state"][w * env.dims.G : (w + 1) * env.dims.G],
                float(b["x"][i]),
                float(b["y"][i]),
                float(b["heading"][i]),
                radius=radius,
                max_road=max_road,
            )
            gr = obs["road"][i]
            assert int(gr[:, 0].sum()) == len(road)
            np.testing.assert_allclose(_sorted_rows(gr[gr[:, 0] > 0]), _sorted_rows(road), atol=2e-5)
            assert b["road_n"][i] == len(road)
            bound += len(road) == max_road
            objs = ref.object_rows(b, env.dims, i, radius=radius)
            near = objs[np.argsort(objs[:, 1] ** 2 + objs[:, 2] ** 2, kind="stable")][:max_objects]
            got = obs["objects"][i]
            np.testing.assert_allclose(_sorted_rows(got[got[:, 0] > 0]), _sorted_rows(near), atol=2e-5)
    assert bound > 20  # the road selection was binding often


def test_road_selection_exact_after_teleport(cmap):
    """Positions written from outside (log replay does this) move an agent farther than one
    step: the distance bound is taken from the last gather's position, so rows stay exact."""
    from selfplaydrive.obs.config import ObsConfig

    env = random_env(cmap, BicycleModel(), 8, obs=ObsConfig(4, 10, 100.0))
    b, L = env.buffers, env.layout
    zero = np.tile(np.array([3, 6]), (env.num_agents, 1))
    env.step(zero)
    live = np.flatnonzero(env.masks)
    b["x"][live] += 60.0  # far beyond the shell of the previous bound
    env.step(zero)
    checked = 0
    for i in np.flatnonzero(env.masks):
        w = i // env.dims.A
        if b["step"][w] != 2:
            continue  # world was reset in between
        road = ref.road_rows(
            cmap,
            b["light_state"][w * env.dims.G : (w + 1) * env.dims.G],
            float(b["x"][i]),
            float(b["y"][i]),
            float(b["heading"][i]),
            max_road=10,
        )
        gr = L.split(env.observations)["road"][i]
        np.testing.assert_allclose(_sorted_rows(gr[gr[:, 0] > 0]), _sorted_rows(road), atol=2e-5)
        checked += 1
    assert checked > 3


def test_lights_match_reference(cmap):
    """Random light states and countdowns (many near or past zero, so groups change often),
    then one kernel step per round against `reference.light_step` on the same random stream."""
    env = VecEnv(cmap, RandomSpawner(A=2, S=0, P=0), 64, physics=BicycleModel(), seed=9)
    env.reset(9)
    rng = np.random.default_rng(5)
    b, G = env.buffers, env.dims.G
    zero = np.tile(np.array([3, 6]), (env.num_agents, 1))
    changed = checked = 0
    for _ in range(10):
        b["lights_on"][:] = 1  # every world steps its lights, whatever the spawner drew
        b["light_state"][:] = rng.integers(0, 4, size=b["light_state"].shape)
        b["light_time"][:] = rng.uniform(-0.2, 0.4, size=b["light_time"].shape)
        pre = {k: b[k].copy() for k in ("light_state", "light_time", "rng_key", "rng_ctr")}
        env.step(zero)
        for w in np.flatnonzero(b["step"] > 0):  # worlds reset by this step were repacked
            g = slice(w * G, (w + 1) * G)
            state, left, ctr = ref.light_step(
                pre["light_state"][g], pre["light_time"][g], int(pre["rng_key"][w]), int(pre["rng_ctr"][w])
            )
            np.testing.assert_array_equal(b["light_state"][g], state)
            np.testing.assert_allclose(b["light_time"][g], left, rtol=1e-6, atol=1e-6)
            assert int(b["rng_ctr"][w]) == ctr
            changed += int(np.sum(state != pre["light_state"][g]))
            checked += G
    assert G >= 2 and checked > 500
    assert changed > checked // 4  # the changes were exercised, and a change never repeats a state
