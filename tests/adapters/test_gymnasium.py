"""Gymnasium adapters: the vector view (same-step autoreset, inactive slots, final
observations) and the single-agent env (check_env, seeding, the three kinds of `others`)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.vector import AutoresetMode

from selfplaydrive.env import GymVectorEnv, SingleAgentEnv
from selfplaydrive.sim import VecEnv


@pytest.fixture
def ended_env(straight_map, sim_helpers):
    """Two worlds: agent 0 leaves the road (C_offroad 0.9 terminates it) in its first step,
    agent 1 drives on; the episode lasts 1 s (10 steps)."""
    h = sim_helpers
    sc = h.make_scenario(
        [dict(xy=(0, -3.2), speed=5.0, coeffs=dict(offroad=0.9)), dict(xy=(20, 0), speed=3.0)],
        episode_length=1.0,
    )
    return VecEnv(straight_map, h.FixedSpawner(sc), 2)


def test_vector_env_spaces_and_autoreset_mode(ended_env):
    venv = GymVectorEnv(ended_env)
    assert venv.metadata["autoreset_mode"] is AutoresetMode.SAME_STEP
    assert venv.num_envs == 8
    assert venv.observation_space.shape == (8, ended_env.layout.obs_dim)
    assert venv.action_space.shape == (8, 2)
    obs, info = venv.reset(seed=3)
    assert obs.shape == (8, ended_env.layout.obs_dim) and obs.dtype == np.float32
    np.testing.assert_array_equal(info["active"], [1, 1, 0, 0, 1, 1, 0, 0])
    assert not obs[[2, 3, 6, 7]].any() and obs[[0, 1, 4, 5]].any()


def test_vector_env_termination_inactive_slots_and_same_step_reset(ended_env):
    venv = GymVectorEnv(ended_env)
    venv.reset(seed=0)
    acts = np.tile(np.array([3, 6]), (8, 1))
    obs, rew, term, trunc, info = venv.step(acts)
    # slot 0 terminated by the road-edge event: final observation kept, next observation zeros
    assert term[0] and not trunc[0] and info["_final_obs"][0]
    assert info["final_obs"][0].any() and not obs[0].any()
    assert rew[0] < 0 and not info["active"][0] and info["acted"][0]
    # empty slots: zero reward, never terminated/truncated, zero observations
    assert not (rew[[2, 3]].any() or term[[2, 3]].any() or trunc[[2, 3]].any() or obs[[2, 3]].any())
    for _ in range(8):
        obs, rew, term, trunc, info = venv.step(acts)
        # the ended slot stays inactive: no reward, no flags, zero observation
        assert rew[0] == 0 and not term[0] and not trunc[0] and not obs[0].any()
    before = obs[1].copy()
    obs, rew, term, trunc, info = venv.step(acts)  # 10th step: the time limit
    assert trunc[1] and not term[1] and info["_final_obs"][1]
    assert info["world_reset"][1] and info["active"][0]  # resampled world: slot 0 active again
    assert not np.array_equal(info["final_obs"][1], before)
    # same step: the returned observation is the new episode's first one (speed 5 m/s / 40)
    assert obs[0, 2] == pytest.approx(5.0 / 40.0)
    assert not info["_final_obs"][0]  # slot 0 had already ended: no final observation now


@pytest.fixture(scope="module")
def single_env(grid_map):
    from selfplaydrive.scenario.spawner import PaperSpawner

    sp = PaperSpawner(num_agents=8, num_static=4, num_pedestrians=2, min_region_lane_length=300.0)
    return VecEnv(grid_map, sp, 1)


def test_single_agent_env_passes_gymnasium_check_env(single_env):
    env = SingleAgentEnv(single_env, others="rule_based")
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)  # any checker warning fails the test
        warnings.filterwarnings("ignore", message=".*PaperSpawner placed.*")
        warnings.filterwarnings("ignore", message=".*render.*")
        check_env(env, skip_render_check=True)


def test_single_agent_env_is_deterministic_under_seeding(single_env):
    env = SingleAgentEnv(single_env, others="rule_based")

    def rollout(seed: int) -> np.ndarray:
        obs, _ = env.reset(seed=seed)
        env.action_space.seed(seed)
        out = [obs]
        for _ in range(30):
            obs, r, term, trunc, _ = env.step(env.action_space.sample())
            out.append(np.append(obs, r))
            if term or trunc:
                break
        return np.concatenate(out)

    a, b = rollout(5), rollout(5)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(rollout(6)[:100], a[:100])
    o1, _ = env.reset()
    o2, _ = env.reset()
    assert not np.array_equal(o1, o2), "unseeded resets must give new episodes"


def test_single_agent_env_static_others_stop_and_stay(single_env):
    env = SingleAgentEnv(single_env, others="static")
    env.reset(seed=1)
    others = np.arange(single_env.num_agents) != env.ego
    for _ in range(25):  # 2.5 s of full braking stops anything below 10 m/s
        _, _, term, trunc, _ = env.step(np.array([6, 6]))
        if term or trunc:
            break
    speeds = single_env.state.speed[others & single_env.masks]
    assert speeds.size and np.all(speeds == 0.0)


def test_single_agent_env_callable_others_and_errors(single_env):
    seen = []

    def policy(obs: np.ndarray) -> np.ndarray:
        seen.append(obs.shape)
        a = np.zeros((len(obs), 2), dtype=np.int64)
        a[:, 0] = 6  # full throttle
        a[:, 1] = 6
        return a

    env = SingleAgentEnv(single_env, others=policy)
    env.reset(seed=2)
    v0 = single_env.state.speed.copy()
    env.step(np.array([3, 6]))
    assert seen == [(single_env.num_agents - 1, single_env.layout.obs_dim)]
    others = (np.arange(single_env.num_agents) != env.ego) & single_env.masks
    assert np.all(single_env.state.speed[others] > v0[others])  # the policy's actions were applied
    with pytest.raises(ValueError, match="others: expected 'rule_based', 'static' or a callable"):
        SingleAgentEnv(single_env, others="idm")
    bad = SingleAgentEnv(single_env, others=lambda obs: np.zeros((2, 2), np.int64))
    bad.reset(seed=0)
    with pytest.raises(ValueError, match=r"others policy: expected actions of shape \(7, 2\)"):
        bad.step(np.array([3, 6]))


def test_single_agent_env_ends_with_the_ego(straight_map, sim_helpers):
    h = sim_helpers
    sc = h.make_scenario(
        [dict(xy=(0, -3.2), speed=5.0, coeffs=dict(offroad=0.9)), dict(xy=(20, 0), speed=3.0)],
        episode_length=5.0,
    )
    env = SingleAgentEnv(VecEnv(straight_map, h.FixedSpawner(sc), 1), others="static")
    obs, info = env.reset(seed=0)
    assert info["ego_slot"] == 0
    obs, r, term, trunc, info = env.step(np.array([3, 6]))
    assert term and not trunc and r < 0 and obs.any()  # final observation, not zeros
    with pytest.raises(RuntimeError, match="call reset"):
        env.step(np.array([3, 6]))
    with pytest.raises(ValueError, match="num_worlds=1"):
        SingleAgentEnv(VecEnv(straight_map, h.FixedSpawner(sc), 2))
