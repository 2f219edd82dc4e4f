"""Gymnasium adapters: the vector view (same-step autoreset, inactive slots, final
observations laid out as gymnasium's own SyncVectorEnv lays them out) and the single-agent env
(check_env, seeding, the three kinds of `others`, action checks, use after close)."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.vector import AutoresetMode, SyncVectorEnv

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
    assert info["final_obs"][0] is None  # as in gymnasium: None where no episode ended


class _EndsAt(gym.Env):
    """Toy env whose one episode end comes at its `end`-th step (counted over its lifetime),
    with the per-step info keys of the driving adapters (`events` int, `reward_terms` (8,)
    float32)."""

    observation_space = gym.spaces.Box(-1.0, 1.0, (3,), np.float32)
    action_space = gym.spaces.MultiDiscrete([7, 13])

    def __init__(self, end: int) -> None:
        self.end, self.t = end, 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return np.zeros(3, np.float32), {}

    def step(self, action):
        self.t += 1
        info = {"events": 4, "reward_terms": np.ones(8, np.float32)}
        return np.full(3, 0.5, np.float32), 1.0, self.t == self.end, False, info


def _layout(value: object) -> object:
    """What the infos' structure consists of: dict keys, array dtypes and shapes, element types."""
    if isinstance(value, dict):
        return {k: _layout(v) for k, v in sorted(value.items())}
    if isinstance(value, np.ndarray) and value.dtype == object:
        return ("object", value.shape[1:], sorted({type(v).__name__ for v in value}))
    if isinstance(value, np.ndarray):
        return (value.dtype.str, value.shape[1:])
    return type(value).__name__


FINAL_KEYS = ("final_obs", "_final_obs", "final_info", "_final_info")


def test_vector_final_info_has_the_layout_of_gymnasiums_same_step_sync_vector_env(ended_env):
    ref = SyncVectorEnv([lambda e=e: _EndsAt(e) for e in (1, 3, 3)], autoreset_mode=AutoresetMode.SAME_STEP)
    ref.reset(seed=0)
    *_, ref_info = ref.step(ref.action_space.sample())
    venv = GymVectorEnv(ended_env)
    venv.reset(seed=0)
    *_, info = venv.step(np.tile(np.array([3, 6]), (8, 1)))
    assert set(FINAL_KEYS) <= set(ref_info) and set(FINAL_KEYS) <= set(info)
    assert _layout({k: info[k] for k in FINAL_KEYS}) == _layout({k: ref_info[k] for k in FINAL_KEYS})
    # the masks agree: the ended envs (ref: env 0; ours: agent 0 of both worlds, slots 0 and 4)
    for infos, ended in ((ref_info, [0]), (info, [0, 4])):
        for mask in (infos["_final_obs"], infos["_final_info"], infos["final_info"]["_events"]):
            np.testing.assert_array_equal(np.flatnonzero(mask), ended)
    assert info["final_info"]["events"][0] & 4  # the road-edge event that ended slot 0
    terms = info["final_info"]["reward_terms"]
    assert terms[[0, 4]].all(axis=0).any() and not np.delete(terms, [0, 4], axis=0).any()
    np.testing.assert_array_equal(info["final_obs"][4], ended_env.final_observations[4])
    # a step where nothing ends carries none of the final keys, as gymnasium's
    *_, info = venv.step(np.tile(np.array([3, 6]), (8, 1)))
    *_, ref_info = ref.step(ref.action_space.sample())
    assert not set(FINAL_KEYS) & set(info) and not set(FINAL_KEYS) & set(ref_info)


def test_vector_env_refuses_step_after_close(ended_env):
    venv = GymVectorEnv(ended_env)
    venv.reset(seed=0)
    venv.close()
    assert venv.closed
    with pytest.raises(RuntimeError, match=r"GymVectorEnv\.step: the env is closed"):
        venv.step(np.tile(np.array([3, 6]), (8, 1)))


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


@pytest.mark.parametrize(
    ("action", "message"),
    [
        # a float index is refused, not truncated to [6, 12]
        (
            np.array([6.9, 12.9]),
            r"action = \[ 6\.9 12\.9\]: expected integer indices in \[0, 7\) x \[0, 13\)"
            r".* of an integer dtype, got dtype float64",
        ),
        # NaN is reported as NaN, not as the index -2**63 that a cast makes of it
        (np.array([np.nan, 3.0]), r"action = \[nan  3\.\]: .*got dtype float64"),
        (np.array([7, 3]), r"action\[0\] = 7: expected an integer in \[0, 7\)"),
        (np.array([3, -1]), r"action\[1\] = -1: expected an integer in \[0, 13\)"),
        (np.array([3, 4, 5]), r"action: expected shape \(2,\), got shape \(3,\)"),
    ],
)
def test_single_agent_env_refuses_actions_outside_the_space(single_env, action, message):
    env = SingleAgentEnv(single_env, others="static")
    env.reset(seed=0)
    step_before = int(single_env.state.step[0])
    with pytest.raises(ValueError, match=message) as err:
        env.step(action)
    assert "-9223372036854775808" not in str(err.value)
    assert int(single_env.state.step[0]) == step_before  # refused before the native step
    env.step(np.array([6, 12]))  # the in-range neighbour is accepted
    assert int(single_env.state.step[0]) == step_before + 1


def test_single_agent_env_checks_continuous_actions(grid_map):
    from selfplaydrive.scenario.spawner import PaperSpawner
    from selfplaydrive.sim.actions import ContinuousActions

    sp = PaperSpawner(num_agents=4, num_static=0, num_pedestrians=0, min_region_lane_length=300.0)
    env = SingleAgentEnv(VecEnv(grid_map, sp, 1, actions=ContinuousActions()), others="static")
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"action\[1\] = nan: expected a finite number in \[-0\.66"):
        env.step(np.array([1.0, np.nan], np.float32))
    with pytest.raises(ValueError, match=r"action\[0\] = 5\.0: expected a finite number in \[-4\.0, 4\.0\]"):
        env.step(np.array([5.0, 0.0]))
    env.step(np.array([4.0, -np.deg2rad(38.0)]))  # the bounds themselves (float64) are accepted


def test_single_agent_env_refuses_step_after_close(single_env):
    env = SingleAgentEnv(single_env, others="static")
    env.reset(seed=0)
    env.close()
    with pytest.raises(RuntimeError, match=r"SingleAgentEnv\.step: the env is closed"):
        env.step(np.array([3, 6]))
