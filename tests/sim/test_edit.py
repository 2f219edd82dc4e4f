"""The public edits of a running env (sim/edit.py): `VecEnv.set_waypoints`, `set_poses`,
`reset_worlds`. Hand-computed expectations; a bad call names the argument and writes nothing."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import FixedSpawner, cross_map, make_scenario

from selfplaydrive.sim import VecEnv

A, K = 4, 3


@pytest.fixture
def env() -> VecEnv:
    agents = [
        {"xy": (0.0, 0.0), "waypoints": [(10.0, 0.0)]},
        {"xy": (0.0, 20.0), "waypoints": [(10.0, 20.0)]},
    ]
    sc = make_scenario(agents, A=A, K=K)
    e = VecEnv(cross_map(), FixedSpawner(sc), 2, seed=0)
    e.reset(seed=0)
    return e


def test_set_waypoints_writes_the_rows_and_restarts_the_route(env):
    env.buffers["wp_idx"][[0, 5]] = 1
    wps = np.array([[[1, 2], [3, 4], [5, 6]], [[7, 8], [9, 10], [9, 10]]], np.float32)
    env.set_waypoints([0, 5], wps, np.array([3, 2]))
    b = env.buffers
    np.testing.assert_array_equal(b["waypoints"][0], wps[0])
    np.testing.assert_array_equal(b["waypoints"][5], wps[1])
    assert b["num_wp"][[0, 5]].tolist() == [3, 2] and b["wp_idx"][[0, 5]].tolist() == [0, 0]
    assert b["num_wp"][1] == 1  # other rows untouched


@pytest.mark.parametrize(
    ("agents", "wps", "count", "match"),
    [
        ([8], np.zeros((1, K, 2)), [1], r"agents: expected indices in \[0, 8\), got 8"),
        ([0, 0], np.zeros((2, K, 2)), [1, 1], "agents: expected distinct"),
        ([0], np.zeros((1, K + 1, 2)), [1], r"waypoints: expected .* shape \(1, 3, 2\)"),
        ([0], np.zeros((1, K, 2)), [4], r"num_waypoints: expected counts in \[0, 3\], got 4"),
        ([0], np.zeros((1, K, 2)), [1.0], "num_waypoints: expected 1 integers"),
        ([0], np.array([[[0, 0], [np.nan, 0], [0, 0]]]), [2], "waypoints: expected finite points"),
    ],
)
def test_set_waypoints_refuses_bad_input_and_writes_nothing(env, agents, wps, count, match):
    before = {k: env.buffers[k].copy() for k in ("waypoints", "num_wp", "wp_idx")}
    with pytest.raises(ValueError, match=match):
        env.set_waypoints(agents, wps, np.array(count))
    for k, v in before.items():
        np.testing.assert_array_equal(env.buffers[k], v)


def test_a_nan_past_the_count_is_padding(env):
    env.set_waypoints([1], np.array([[[4, 0], [np.nan, 0], [np.nan, 0]]]), np.array([1]))
    assert env.buffers["num_wp"][1] == 1


def test_set_poses_writes_pose_heading_cache_and_speed(env):
    env.set_poses(
        [1, 6], np.array([[3.0, 4.0], [-1.0, 2.0]]), np.array([np.pi / 2, 0.0]), np.array([5.0, 0.0])
    )
    b = env.buffers
    assert b["x"][[1, 6]].tolist() == [3.0, -1.0] and b["y"][[1, 6]].tolist() == [4.0, 2.0]
    assert b["heading"][1] == np.float32(np.pi / 2) and b["hcos"][6] == 1.0 and b["hsin"][6] == 0.0
    assert abs(b["hcos"][1]) < 1e-7 and b["hsin"][1] == 1.0
    assert b["speed"][[1, 6]].tolist() == [5.0, 0.0]


def test_set_poses_then_step_moves_from_the_new_pose(env):
    """Speed 5 m/s north from (1.75, 10) on the north-bound lane, accel and steer 0: the centre
    moves 5 * 0.1 = 0.5 m in y in one step."""
    env.set_poses([1], np.array([[1.75, 10.0]]), np.array([np.pi / 2]), np.array([5.0]))
    acts = np.zeros((env.num_agents, 2), np.int64)
    t = env.action_table
    acts[:, 0] = int(np.argmin(np.abs(t.accel)))
    acts[:, 1] = int(np.argmin(np.abs(t.steer)))
    env.step(acts)
    assert env.buffers["py"][1] == 10.0
    assert abs(env.buffers["y"][1] - 10.5) < 1e-3 and abs(env.buffers["x"][1] - 1.75) < 1e-3


@pytest.mark.parametrize(
    ("heading", "speed", "match"),
    [(4.0, 1.0, r"heading: expected radians in \[-pi, pi\]"), (0.0, -1.0, "speed: expected speeds >= 0")],
)
def test_set_poses_refuses_bad_values(env, heading, speed, match):
    x = env.buffers["x"].copy()
    with pytest.raises(ValueError, match=match):
        env.set_poses([0], np.array([[9.0, 9.0]]), np.array([heading]), np.array([speed]))
    np.testing.assert_array_equal(env.buffers["x"], x)
    with pytest.raises(ValueError, match=r"xy: expected shape \(1, 2\)"):
        env.set_poses([0], np.array([9.0, 9.0]), np.array([0.0]), np.array([1.0]))


def test_reset_worlds_with_a_scenario_restarts_that_world_only(env):
    acts = np.zeros((env.num_agents, 2), np.int64)
    for _ in range(3):
        env.step(acts)
    other = make_scenario([{"xy": (50.0, 0.0)}], A=A, K=K)
    env.reset_worlds([1], [other])
    b = env.buffers
    assert b["step"].tolist() == [3, 0]
    assert b["x"][A] == 50.0 and b["active"][A : 2 * A].tolist() == [1, 0, 0, 0]


def test_reset_worlds_refuses_bad_worlds_and_scenarios(env):
    with pytest.raises(ValueError, match=r"worlds: expected distinct indices in \[0, 2\)"):
        env.reset_worlds([2])
    with pytest.raises(ValueError, match=r"scenarios: expected one per world \(1\), got 2"):
        env.reset_worlds([0], [None, None])
    bad = make_scenario([{"xy": (0.0, 0.0), "length": 0.0}], A=A, K=K)
    with pytest.raises(ValueError, match=r"scenario\.agent_length: expected positive finite sizes"):
        env.reset_worlds([0], [bad])
