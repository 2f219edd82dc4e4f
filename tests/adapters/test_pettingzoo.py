"""PettingZoo adapter: PettingZoo's own API, seed and render tests, agents leaving on
termination, everyone leaving at truncation, action checks, use after close."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test, parallel_seed_test, render_test
from pettingzoo.utils.conversions import parallel_to_aec

from selfplaydrive.env import DrivingParallelEnv
from selfplaydrive.sim import VecEnv


def test_parallel_api_test_passes(make_env):
    env = DrivingParallelEnv(make_env(1, episode_lengths=(3.0,)))
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*PaperSpawner placed.*")
        parallel_api_test(env, num_cycles=100)
    assert env.possible_agents == [f"agent_{i}" for i in range(8)]


def test_parallel_seed_test_passes(make_env):
    parallel_seed_test(lambda: DrivingParallelEnv(make_env(1, episode_lengths=(2.0,))), num_cycles=50)


def test_terminated_agents_leave_and_truncation_ends_everyone(straight_map, sim_helpers):
    h = sim_helpers
    sc = h.make_scenario(
        [
            dict(xy=(0, -3.2), speed=5.0, coeffs=dict(offroad=0.9)),
            dict(xy=(20, 0), speed=3.0),
            dict(xy=(60, 0), speed=3.0),
        ],
        episode_length=1.0,
    )
    env = DrivingParallelEnv(VecEnv(straight_map, h.FixedSpawner(sc), 1))
    obs, _ = env.reset(seed=0)
    assert env.agents == ["agent_0", "agent_1", "agent_2"] and set(obs) == set(env.agents)
    go = np.array([3, 6])
    obs, rew, term, trunc, info = env.step({a: go for a in env.agents})
    assert term == {"agent_0": True, "agent_1": False, "agent_2": False}
    assert rew["agent_0"] < 0 and obs["agent_0"].any()  # its final observation
    assert info["agent_0"]["events"] & 4  # the road-edge event that ended it
    assert env.agents == ["agent_1", "agent_2"]
    with pytest.raises(ValueError, match=r"'agent_0' is not in env\.agents"):
        env.step({"agent_0": go})
    for _ in range(8):
        obs, _, _, trunc, _ = env.step({a: go for a in env.agents})
        assert set(obs) == {"agent_1", "agent_2"} and not any(trunc.values())
    obs, rew, term, trunc, _ = env.step({a: go for a in env.agents})  # 1 s: time limit
    assert trunc == {"agent_1": True, "agent_2": True} and not any(term.values())
    assert env.agents == []
    assert env.step({}) == ({}, {}, {}, {}, {})
    assert env.observation_space("agent_1") is env.observation_space("agent_1")
    with pytest.raises(ValueError, match=r"expected one of agent_0\.\.agent_3"):
        env.action_space("car_1")


def test_render_test_passes_with_rgb_array_images(make_env):
    def env_fn(render_mode=None):
        # render_test builds its first env with "human" only to read metadata["render_modes"];
        # this env has no window, so that one is built without a render mode
        mode = None if render_mode == "human" else render_mode
        return parallel_to_aec(DrivingParallelEnv(make_env(1, episode_lengths=(3.0,)), render_mode=mode))

    def drawn(image: np.ndarray) -> bool:  # a picture, not a blank canvas
        return image.shape == (400, 400, 3) and len(np.unique(image.reshape(-1, 3), axis=0)) > 20

    assert DrivingParallelEnv.metadata["render_modes"] == ["rgb_array"]
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*PaperSpawner placed.*")
        render_test(env_fn, custom_tests={"rgb_array": drawn})


def test_render_follows_the_world(make_env):
    env = DrivingParallelEnv(make_env(1, episode_lengths=(3.0,)), render_mode="rgb_array", render_size=128)
    env.reset(seed=0)
    first = env.render()
    assert first.shape == (128, 128, 3) and first.dtype == np.uint8
    for _ in range(10):  # full throttle for 1 s: the cars move
        env.step({a: np.array([6, 6]) for a in env.agents})
    assert not np.array_equal(env.render(), first)
    env.reset(seed=0)
    np.testing.assert_array_equal(env.render(), first)  # same episode, same picture
    plain = DrivingParallelEnv(make_env(1))
    plain.reset(seed=0)
    with pytest.warns(UserWarning, match="no render_mode was given"):
        assert plain.render() is None
    with pytest.raises(
        ValueError, match=r"render_mode: expected None or one of \('rgb_array',\), got 'human'"
    ):
        DrivingParallelEnv(make_env(1), render_mode="human")
    with pytest.raises(
        ValueError, match=r"render_size: expected an integer number of pixels in \[64, 8192\], got 8"
    ):
        DrivingParallelEnv(make_env(1), render_mode="rgb_array", render_size=8)


def test_actions_are_checked_and_step_after_close_raises(make_env):
    env = DrivingParallelEnv(make_env(1))
    env.reset(seed=0)
    name = env.agents[0]
    with pytest.raises(ValueError, match=rf"actions\['{name}'\] = \[ 6\.9 12\.9\]: .*integer dtype"):
        env.step({name: np.array([6.9, 12.9])})
    with pytest.raises(ValueError, match=rf"actions\['{name}'\] = \[nan  3\.\]"):
        env.step({name: np.array([np.nan, 3.0])})
    with pytest.raises(ValueError, match=rf"actions\['{name}'\]\[1\] = 13: expected an integer in \[0, 13\)"):
        env.step({name: np.array([3, 13])})
    assert int(env.env.state.step[0]) == 0  # nothing was stepped
    env.close()
    with pytest.raises(RuntimeError, match=r"DrivingParallelEnv\.step: the env is closed"):
        env.step({name: np.array([3, 6])})
