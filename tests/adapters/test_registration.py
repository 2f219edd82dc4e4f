"""Gymnasium ids: `gymnasium.make` / `make_vec` build the adapters, and registering them on
`import selfplaydrive` imports nothing heavy."""

from __future__ import annotations

import subprocess
import sys
import warnings

import gymnasium as gym
import numpy as np
import pytest

import selfplaydrive  # noqa: F401  (registers the ids)
from selfplaydrive.env import GymVectorEnv, SingleAgentEnv
from selfplaydrive.env.registration import SELF_PLAY_ID, SINGLE_AGENT_ID, register_envs

SMALL = {"num_agents": 8, "num_static": 4, "num_pedestrians": 2, "min_region_lane_length": 300.0}


@pytest.fixture(autouse=True)
def _quiet_spawner():
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*PaperSpawner placed.*")
        yield


def test_make_builds_the_single_agent_env(grid_map):
    env = gym.make(SINGLE_AGENT_ID, map=grid_map, spawner=SMALL, others="static", seed=3)
    assert isinstance(env.unwrapped, SingleAgentEnv) and env.unwrapped.others == "static"
    assert env.spec is not None and env.spec.id == SINGLE_AGENT_ID  # kwargs copied into the spec
    assert env.unwrapped.env.num_agents == 8 and env.unwrapped.env.num_worlds == 1
    obs, info = env.reset(seed=0)
    assert obs.shape == env.observation_space.shape and "ego_slot" in info
    obs2, *_ = env.step(np.array([3, 6]))
    assert obs2.dtype == np.float32
    env.close()


@pytest.mark.parametrize("kind", ["sampler", "settings"])
def test_make_takes_the_reward_group(grid_map, kind):
    """`reward=`: a conditioning sampler goes to the spawner; `RewardSettings` (the reward
    group) also brings its constants and terms."""
    from selfplaydrive.scenario.conditioning import ConditioningSampler
    from selfplaydrive.sim.reward_settings import RewardSettings

    settings = RewardSettings(comfort=(0.0, 0.05), velocity_reward=0.01, terms={"velocity": 1.0})
    reward = settings if kind == "settings" else ConditioningSampler(comfort=(0.0, 0.05))
    env = gym.make(SINGLE_AGENT_ID, map=grid_map, spawner=SMALL, others="static", reward=reward).unwrapped.env
    assert env.spawner.conditioning.comfort == (0.0, 0.05) and env.params.coeff_scale[4] == 0.05
    want = (0.01, ("velocity",)) if kind == "settings" else (2.5e-4, tuple(env.term_names))
    assert (env.params.velocity_reward, tuple(env.term_names)) == want


def test_make_vec_of_the_single_agent_id_uses_gymnasiums_vectorization(grid_map):
    venv = gym.make_vec(SINGLE_AGENT_ID, num_envs=2, map=grid_map, spawner=SMALL, others="static")
    assert isinstance(venv, gym.vector.SyncVectorEnv) and venv.num_envs == 2
    obs, _ = venv.reset(seed=0)
    assert obs.shape[0] == 2
    venv.close()


def test_make_vec_builds_the_self_play_vector_env(grid_map):
    venv = gym.make_vec(SELF_PLAY_ID, num_envs=16, map=grid_map, spawner=SMALL)
    assert isinstance(venv, GymVectorEnv)
    assert venv.num_envs == 16 and venv.env.num_worlds == 2  # 16 slots = 2 worlds x 8 agents
    assert venv.spec is not None and venv.spec.id == SELF_PLAY_ID
    obs, info = venv.reset(seed=0)
    assert obs.shape == (16, venv.single_observation_space.shape[0]) and info["active"].any()
    with pytest.raises(
        ValueError, match=r"num_envs: expected a positive multiple of the 8 agent slots per world"
    ):
        gym.make_vec(SELF_PLAY_ID, num_envs=12, map=grid_map, spawner=SMALL)
    with pytest.raises(gym.error.Error):  # a sub-env is an agent slot: no single-env entry point
        gym.make(SELF_PLAY_ID)


def test_register_envs_is_idempotent():
    before = gym.registry[SINGLE_AGENT_ID]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # gymnasium warns when an id is registered again
        register_envs()
    assert gym.registry[SINGLE_AGENT_ID] is before
    assert isinstance(before.entry_point, str) and isinstance(
        gym.registry[SELF_PLAY_ID].vector_entry_point, str
    )


def test_importing_selfplaydrive_registers_without_heavy_imports():
    heavy = ["torch", "matplotlib", "scipy", "pettingzoo", "stable_baselines3", "selfplaydrive.sim.vec_env"]
    code = (
        "import sys, selfplaydrive, gymnasium\n"
        f"print(sorted(m for m in {heavy!r} if m in sys.modules))\n"
        "print(sorted(k for k in gymnasium.registry if k.startswith('selfplaydrive/')))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    loaded, ids = out.splitlines()
    assert loaded == "[]"
    assert ids == str(sorted([SINGLE_AGENT_ID, SELF_PLAY_ID]))
