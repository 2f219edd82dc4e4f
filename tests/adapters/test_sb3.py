"""stable-baselines3 adapter: SB3's env checker on the single-agent env, the per-slot done /
terminal_observation / TimeLimit.truncated rules, and PPO running on the adapter."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from selfplaydrive.env import SB3VecEnv, SingleAgentEnv
from selfplaydrive.sim import VecEnv


def test_sb3_check_env_on_single_agent_env(grid_map):
    from stable_baselines3.common.env_checker import check_env

    from selfplaydrive.scenario.spawner import PaperSpawner

    sp = PaperSpawner(num_agents=8, num_static=4, num_pedestrians=2, min_region_lane_length=300.0)
    env = SingleAgentEnv(VecEnv(grid_map, sp, 1), others="rule_based")
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        warnings.filterwarnings("ignore", message=".*PaperSpawner placed.*")
        check_env(env, warn=True)


def test_dones_terminal_observations_and_inactive_slots(straight_map, sim_helpers):
    h = sim_helpers
    sc = h.make_scenario(
        [dict(xy=(0, -3.2), speed=5.0, coeffs=dict(offroad=0.9)), dict(xy=(20, 0), speed=3.0)],
        episode_length=1.0,
    )
    venv = SB3VecEnv(VecEnv(straight_map, h.FixedSpawner(sc), 1), seed=0)
    obs = venv.reset()
    assert obs.shape == (4, venv.observation_space.shape[0]) and not obs[2:].any()
    acts = np.tile(np.array([3, 6]), (4, 1))
    obs, rew, dones, infos = venv.step(acts)
    # slot 0: event termination -> done, final observation kept, no bootstrap
    assert dones[0] and infos[0]["terminal_observation"].any()
    assert infos[0]["TimeLimit.truncated"] is False and not obs[0].any()
    assert not dones[1] and not dones[2] and infos[2]["inactive"] and rew[2] == 0
    for _ in range(8):
        obs, rew, dones, infos = venv.step(acts)
        assert not dones.any() and rew[0] == 0 and infos[0]["inactive"] and not obs[0].any()
    obs, rew, dones, infos = venv.step(acts)  # time limit, world resampled
    # slot 1: truncated -> bootstrapped from its terminal observation
    assert dones[1] and infos[1]["TimeLimit.truncated"] is True and infos[1]["terminal_observation"].any()
    # inactive slots are cut at the world reset: done, zero terminal observation, no bootstrap
    for i in (0, 2, 3):
        assert dones[i] and infos[i]["TimeLimit.truncated"] is False
        assert not infos[i]["terminal_observation"].any() and rew[i] == 0
    assert obs[0].any() and obs[1].any() and not obs[2].any()  # new episode: slots 0, 1 filled


def test_ppo_runs_on_the_adapter(make_env):
    import torch
    from stable_baselines3 import PPO

    torch.set_num_threads(1)
    venv = SB3VecEnv(make_env(2, num_agents=8, episode_lengths=(3.0,)), seed=0)
    model = PPO(
        "MlpPolicy", venv, n_steps=16, batch_size=64, n_epochs=1, seed=0, policy_kwargs=dict(net_arch=[32])
    )
    before = [p.detach().clone() for p in model.policy.parameters()]
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*PaperSpawner placed.*")
        model.learn(total_timesteps=16 * 16 * 2)
    assert model.num_timesteps >= 512
    changed = [not torch.equal(a, b) for a, b in zip(before, model.policy.parameters(), strict=True)]
    assert all(changed)
    acts, _ = model.predict(venv.reset(), deterministic=True)
    assert acts.shape == (16, 2) and venv.action_space.contains(acts[0])


def test_seed_controls_the_episode(make_env):
    venv = SB3VecEnv(make_env(1), seed=4)
    a = venv.reset().copy()
    venv.seed(4)
    np.testing.assert_array_equal(venv.reset(), a)
    assert not np.array_equal(venv.reset(), a)  # unseeded: the next episode
    with pytest.raises(RuntimeError, match="step_async"):
        venv.step_wait()


def test_step_after_close_raises(make_env):
    venv = SB3VecEnv(make_env(1), seed=0)
    venv.reset()
    acts = np.tile(np.array([3, 6]), (venv.num_envs, 1))
    venv.step(acts)
    venv.close()
    with pytest.raises(RuntimeError, match=r"SB3VecEnv\.step_async: the env is closed"):
        venv.step(acts)
    with pytest.raises(RuntimeError, match=r"SB3VecEnv\.step_wait: the env is closed"):
        venv.step_wait()
