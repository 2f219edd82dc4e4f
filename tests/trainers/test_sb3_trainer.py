"""`trainer=sb3`: the Deep Sets feature extractor is a set function (order and padding do not
matter), the config file lists exactly the constructor arguments, bad values name their key,
and `selfplaydrive train trainer=sb3` writes a run folder with a loadable model."""

from __future__ import annotations

import inspect
import json
import warnings

import numpy as np
import pytest
import torch
from gymnasium import spaces
from omegaconf import OmegaConf

from selfplaydrive.builder import compose
from selfplaydrive.errors import ConfigError
from selfplaydrive.obs.layout import ObsLayout
from selfplaydrive.trainers.sb3 import DeepSetsExtractor, SB3Trainer

TINY_ENV = (
    "env.num_worlds=1",
    "spawner.num_agents=6",
    "spawner.num_static=4",
    "spawner.num_pedestrians=2",
    "spawner.episode_lengths=[2.0]",
)


def _obs(layout: ObsLayout, batch: int, n_obj: int, n_road: int, seed: int = 0) -> np.ndarray:
    """Random rows with the first n_obj objects and n_road road segments valid, rest padding."""
    rng = np.random.default_rng(seed)
    obs = rng.uniform(-1, 1, size=(batch, layout.obs_dim)).astype(np.float32)
    parts = layout.split(obs)
    objects, road = parts["objects"], parts["road"]
    objects[:, :, 0] = 0.0
    objects[:, :n_obj, 0] = 1.0
    road[:, :, 0] = 0.0
    road[:, :n_road, 0] = 1.0
    road[:, :, layout.feature_index("road", "type")] = rng.integers(0, 5, size=road.shape[:2]) / 4.0
    return obs


def _extractor(layout: ObsLayout) -> DeepSetsExtractor:
    torch.manual_seed(0)
    low, high = layout.bounds()
    return DeepSetsExtractor(spaces.Box(low, high, dtype=np.float32), layout.__dict__, 16, 32)


def test_extractor_is_invariant_to_element_order_and_padding():
    layout = ObsLayout(max_objects=5, max_road=7)
    ext = _extractor(layout)
    obs = _obs(layout, batch=3, n_obj=4, n_road=6)
    base = ext(torch.from_numpy(obs))
    assert base.shape == (3, 32)

    shuffled = obs.copy()
    parts = layout.split(shuffled)
    parts["objects"][:] = parts["objects"][:, [3, 0, 4, 2, 1]]  # padding slot moves to the middle
    parts["road"][:] = parts["road"][:, [6, 5, 0, 1, 4, 2, 3]]
    torch.testing.assert_close(ext(torch.from_numpy(shuffled)), base, rtol=0, atol=1e-6)

    padded = obs.copy()
    parts = layout.split(padded)
    parts["objects"][:, 4, 1:] = 0.9  # features of padded elements are ignored
    parts["road"][:, 6, 1:6] = -0.7
    torch.testing.assert_close(ext(torch.from_numpy(padded)), base, rtol=0, atol=1e-6)

    changed = obs.copy()
    layout.split(changed)["objects"][:, 0, 1:3] += 0.5  # a valid element moves: the output must too
    assert not torch.allclose(ext(torch.from_numpy(changed)), base)


def test_extractor_rejects_a_space_of_another_layout():
    layout = ObsLayout(max_objects=5, max_road=7)
    box = spaces.Box(-1, 1, shape=(layout.obs_dim + 3,), dtype=np.float32)
    with pytest.raises(ConfigError, match=r"obs_dim"):
        DeepSetsExtractor(box, layout)


def test_yaml_lists_every_constructor_argument():
    cfg = compose("train", ["trainer=sb3"])
    keys = set(OmegaConf.to_container(cfg.trainer)) - {"_target_"}
    assert keys == set(inspect.signature(SB3Trainer).parameters)
    assert cfg.trainer.seed == cfg.seed


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"n_steps": 0}, r"trainer\.n_steps: expected an integer >= 1, got 0"),
        ({"gamma": 1.5}, r"trainer\.gamma: expected a number in \[0, 1\], got 1\.5"),
        ({"device": "tpu"}, r"trainer\.device: expected one of"),
        ({"net_arch": [64, 0]}, r"trainer\.net_arch"),
    ],
)
def test_bad_values_name_the_key(kwargs, match):
    with pytest.raises(ConfigError, match=match):
        SB3Trainer(**kwargs)


def test_run_saves_model_and_eval(tmp_path):
    from stable_baselines3 import PPO

    from selfplaydrive.builder import build_env

    env = build_env(compose("sim", list(TINY_ENV)))
    trainer = SB3Trainer(
        total_timesteps=96,
        n_steps=8,
        batch_size=24,
        n_epochs=1,
        eval_episodes=1,
        eval_max_steps=30,
        embed_size=8,
        features_dim=16,
        net_arch=[16],
        device="cpu",
    )
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*PaperSpawner placed.*")
        out = trainer.run(env, None, tmp_path)
    assert out["agent_steps"] >= 96
    summary = json.loads((tmp_path / "eval.json").read_text())
    assert summary["episodes"] >= 1 and 0.0 <= summary["collision_rate"] <= 1.0
    model = PPO.load(tmp_path / "model.zip", device="cpu")
    assert isinstance(model.action_space, spaces.MultiDiscrete)
    assert isinstance(model.policy.features_extractor, DeepSetsExtractor)
    actions, _ = model.predict(np.zeros((2, env.layout.obs_dim), np.float32), deterministic=True)
    assert actions.shape == (2, 2) and env.action_space.contains(actions[0])


def test_cli_train_trainer_sb3_writes_the_run_folder(tmp_path):
    """Continuous actions too: the SB3 path builds its own policy (the library models need
    MultiDiscrete actions and are not built for it)."""
    from stable_baselines3 import PPO

    from selfplaydrive.hydra_app import run_hydra, train_task

    run_dir = tmp_path / "run"
    argv = [
        "trainer=sb3",
        "env/actions=continuous",
        "trainer.total_timesteps=96",
        "trainer.n_steps=8",
        "trainer.batch_size=24",
        "trainer.n_epochs=1",
        "trainer.eval_episodes=1",
        "trainer.eval_max_steps=30",
        "trainer.device=cpu",
        "seed=3",
        *TINY_ENV,
        f"hydra.run.dir={run_dir}",
    ]
    assert run_hydra("train", train_task, argv) == 0
    for name in ("model.zip", "eval.json", "sb3_config.json", "resolved_config.yaml", "run_meta.json"):
        assert (run_dir / name).is_file(), name
    assert list((run_dir / "tb").glob("events.out.tfevents.*"))
    meta = json.loads((run_dir / "run_meta.json").read_text())
    assert meta["seed"] == 3 and meta["choices"]["trainer"] == "sb3"
    used = json.loads((run_dir / "sb3_config.json").read_text())
    assert used["seed"] == 3 and used["n_steps"] == 8
    summary = json.loads((run_dir / "eval.json").read_text())
    assert {"waypoint_completion", "collision_rate", "offroad_rate"} <= set(summary)
    assert isinstance(PPO.load(run_dir / "model.zip", device="cpu").action_space, spaces.Box)
