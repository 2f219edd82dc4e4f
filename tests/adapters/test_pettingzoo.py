"""PettingZoo adapter: PettingZoo's own API and seed tests, agents leaving on termination,
everyone leaving at truncation."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test, parallel_seed_test

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
