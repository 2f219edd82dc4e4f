"""The ``reward`` config group holds every reward setting (issue #13 item 4): distributions,
terms, the reward constants and the observed-coefficient scale derived from the ranges; the
spawner config no longer interpolates it; saved configs of the old layout still load."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from helpers import FixedSpawner, make_scenario
from omegaconf import OmegaConf

from selfplaydrive.builder import build_env, build_spawner, compose, make_env
from selfplaydrive.errors import ConfigError
from selfplaydrive.physics import BicycleModel
from selfplaydrive.rewards import TERM_NAMES
from selfplaydrive.scenario.conditioning import PAPER, ConditioningSampler
from selfplaydrive.scenario.types import COEFF_NAMES
from selfplaydrive.sim.params import COEFF_SCALE
from selfplaydrive.sim.reward_settings import CONSTANTS, RewardSettings

OLD_CONFIG = Path(__file__).resolve().parents[1] / "trainers" / "data" / "resolved_config_20eb9be.yaml"


def test_spawner_config_has_no_reward_interpolation():
    cfg = compose("train")
    text = OmegaConf.to_yaml(cfg.spawner, resolve=False)
    assert "conditioning" not in cfg.spawner and "${reward" not in text


def test_paper_ranges_give_the_paper_scale_exactly():
    """The digests rest on it: the derived scale of the paper's ranges is COEFF_SCALE."""
    assert ConditioningSampler().observation_scale() == COEFF_SCALE
    assert ConditioningSampler(mode="eval").observation_scale() == COEFF_SCALE
    for option in ("paper", "eval"):
        settings = build_env_settings([f"reward={option}", "experiment=paper_deepsets"])
        assert settings.coeff_scale == COEFF_SCALE
    env = make_env("default", num_worlds=1)
    np.testing.assert_array_equal(env.params.kernel_params()["coeff_scale"], np.float32(COEFF_SCALE))


def build_env_settings(overrides):
    from selfplaydrive.builder import build_reward

    return build_reward(compose("train", overrides))


def test_paper_yaml_writes_out_the_one_table_of_ranges():
    """conf/reward/paper.yaml, ConditioningSampler and RewardSettings give the same distributions:
    the constructors default to `PAPER`, and the YAML writes every entry of it out."""
    node = compose("train", ["reward=paper"]).reward
    for key, value in PAPER.items():
        written = node[key]
        got = (written.low, written.high) if isinstance(value, tuple) else written
        assert got == value, key
    sampler, settings = ConditioningSampler(), RewardSettings().conditioning
    for key, value in PAPER.items():
        assert getattr(sampler, key) == value == getattr(settings, key), key
    assert PAPER["center_low"] == (2.5e-5, 2.5e-4) and PAPER["waypoint_radius"] == (1.0, 3.0)


def test_scale_hand_computed_from_the_ranges():
    s = ConditioningSampler(
        waypoint_radius=(1.0, 2.0), eval_waypoint_radius=4.0, comfort=(0.0, 0.05),
        center_low=(-0.01, 1e-3), center_high=(1e-3, 2e-3), center_bias=(-0.5, 0.2),
        collision=(0.0, 0.0),
    )  # fmt: skip
    scale = dict(zip(COEFF_NAMES, s.observation_scale(), strict=True))
    assert scale["waypoint_radius"] == 4.0  # the eval value is the largest
    assert scale["comfort"] == 0.05
    assert scale["center"] == 0.01  # |low end| of the low mode
    assert scale["center_bias"] == 0.5
    assert scale["collision"] == 1.0  # fixed at 0: observed as 0


def test_sweep_beyond_the_old_scale_rescales_the_observation():
    """`reward.comfort.high=0.05` (5x the paper's 0.01, the old fixed scale): the observed
    coefficients stay in [-1, 1] and distinct coefficients stay distinct (no saturation)."""
    env = build_env(compose("sim", ["reward.comfort.high=0.05", "env.num_worlds=2"]))
    assert env.params.coeff_scale[COEFF_NAMES.index("comfort")] == 0.05
    obs = env.reset(seed=0)
    live = env.buffers["active"].astype(bool)
    comfort = env.buffers["coeffs"][live, COEFF_NAMES.index("comfort")]
    seen = env.layout.split(obs)["ego"][live, env.layout.feature_index("ego", "coef_comfort")]
    assert comfort.max() > 0.02  # beyond the old scale: observed as 1 before
    assert np.all(np.abs(seen) <= 1.0)
    np.testing.assert_allclose(seen, comfort / np.float32(0.05), rtol=1e-6)
    assert len(np.unique(seen)) == len(np.unique(comfort))


def _velocity_term(overrides, straight_map):
    """Velocity term of one car on the east lane centre, heading along it at 5 m/s, one step."""
    agents = [dict(xy=(0.0, -2.0), heading=0.0, speed=5.0)]
    spawner = FixedSpawner(make_scenario(agents, episode_length=100.0))
    cfg = compose("sim", overrides)
    env = build_env(cfg, maps=[straight_map], spawner=spawner, physics=BicycleModel(), num_worlds=1)
    env.reset(0)
    env.step(np.tile(np.asarray((3, 6), np.int64), (env.num_agents, 1)))  # no accel, no steer
    assert env.buffers["lane_alpha"][0] == 0.0 and env.buffers["speed"][0] >= 2.5
    return float(env.reward_terms[0, TERM_NAMES.index("velocity")])


def test_reward_constant_override_reaches_the_kernel(straight_map):
    """R_velocity = velocity_reward * cos(alpha) with alpha = 0 (section 2.3): the constant."""
    assert _velocity_term([], straight_map) == np.float32(2.5e-4)
    assert _velocity_term(["reward.velocity_reward=5e-4"], straight_map) == np.float32(5e-4)
    assert _velocity_term(["reward.velocity_min=6.0"], straight_map) == 0.0  # 5 m/s < 6 m/s


def test_old_env_params_key_names_its_new_place():
    with pytest.raises(ConfigError, match=r"velocity_reward' moved to the reward group: use reward.velocity"):
        compose("sim", ["env.params.velocity_reward=0.1"])
    cfg = compose("sim", ["+env.params.velocity_reward=0.1"])  # forced in: the builder maps it
    with pytest.warns(UserWarning, match=r"env.params.velocity_reward -> reward.velocity_reward"):
        env = build_env(cfg)
    assert env.params.velocity_reward == 0.1


@pytest.mark.parametrize(
    "key,value,expected",
    [
        ("velocity_min", 0.0, "reward.velocity_min: expected a positive finite number, got 0.0"),
        ("waypoint_reward", "x", "reward.waypoint_reward: expected a number, got 'x'"),
        ("terminate_threshold", float("nan"), "reward.terminate_threshold: expected a finite number"),
    ],
)
def test_bad_constant_names_key_and_expectation(key, value, expected):
    with pytest.raises(ConfigError, match=expected):
        RewardSettings(**{key: value})


def test_settings_in_plain_python():
    """`make_env(reward=RewardSettings(...))`: sampler to the spawner, constants to the params."""
    settings = RewardSettings(comfort=(0.0, 0.05), waypoint_reward=1.0, terms={"waypoint": 2.0})
    env = make_env("default", num_worlds=1, reward=settings)
    assert env.spawner.conditioning is settings.conditioning
    assert env.params.waypoint_reward == 1.0 and env.params.coeff_scale == settings.coeff_scale
    assert list(env.term_names) == ["waypoint"]
    assert set(CONSTANTS) <= set(vars(env.params))


def test_old_run_config_loads_with_its_settings():
    """A resolved_config.yaml of the old layout (reward constants in env.params, the sampler in
    spawner.conditioning): the trained env gets its constants, the eval its spawner."""
    from selfplaydrive.policies import load_run_config, trained_env_kwargs

    with pytest.warns(UserWarning, match=r"env.params.velocity_reward -> reward.velocity_reward"):
        cfg = load_run_config(OLD_CONFIG)
    params = trained_env_kwargs(cfg)["params"]
    assert (params.velocity_reward, params.waypoint_reward, params.terminate_threshold) == (0.02, 1.0, 0.0)
    assert params.coeff_scale == COEFF_SCALE and params.wp_scale == 50.0
    spawner = build_spawner(cfg)
    assert spawner.conditioning.mode == "train" and spawner.conditioning.comfort == (0.0, 0.01)
    env = build_env(cfg, num_worlds=1)
    assert env.params == params and list(env.term_names) == list(TERM_NAMES)


def test_upgrade_maps_every_old_key():
    """The old layout's three places become the reward node; a current config is unchanged."""
    from selfplaydrive.sim.reward_settings import TARGET, upgrade_run_config

    sampler = "selfplaydrive.scenario.conditioning.ConditioningSampler"
    old = OmegaConf.create(
        {
            "reward": {
                "_target_": sampler,
                "collision": {"low": 0.0, "high": 1.0},
                "terms": {"waypoint": 1.0},
            },
            "spawner": {
                "num_agents": 4,
                "conditioning": {"_target_": sampler, "collision": {"low": 0.0, "high": 0.5}},
            },
            "env": {"params": {"dt": 0.1, "velocity_reward": 0.02}},
        }
    )
    with pytest.warns(UserWarning, match="env.params.velocity_reward -> reward.velocity_reward"):
        upgrade_run_config(old)
    want = {
        "_target_": TARGET,
        "collision": {"low": 0.0, "high": 0.5},  # what the spawner drew from
        "terms": {"waypoint": 1.0},
        "velocity_reward": 0.02,
    }
    assert OmegaConf.to_container(old.reward) == want
    assert OmegaConf.to_container(old.spawner) == {"num_agents": 4}
    assert OmegaConf.to_container(old.env.params) == {"dt": 0.1}
    bare = OmegaConf.create({"env": {"params": {"waypoint_reward": 1.0}}})  # no reward node
    with pytest.warns(UserWarning):
        upgrade_run_config(bare)
    assert OmegaConf.to_container(bare.reward) == {"_target_": TARGET, "waypoint_reward": 1.0}
    current = compose("train")
    before = OmegaConf.to_container(current)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        upgrade_run_config(current)
    assert OmegaConf.to_container(current) == before
