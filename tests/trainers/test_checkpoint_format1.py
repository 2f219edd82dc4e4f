"""Checkpoints of format 1 (before `VecEnv.get_state`) still load and continue exactly.

data/ckpt_format1.pt was written by the code of commit 458b183 (format 1): `lane_env(num_worlds=1,
seed=0, episode_length=1.5)`, `DeepSetsModel(input_size=8, hidden_size=8, lstm_size=8)`, one
update of `CFG` below, `PPOTrainer.save`. data/ckpt_format1_next.npz holds what that env gave over
the next 24 steps of the actions drawn below (crossing an autoreset), from the same code.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from ppo_helpers import lane_env

from selfplaydrive.models import DeepSetsModel
from selfplaydrive.trainers import PPOConfig, PPOTrainer
from selfplaydrive.trainers.ppo import checkpoint as ckpt

DATA = Path(__file__).parent / "data"
CFG = dict(
    total_steps=10_000,
    rollout_length=4,
    num_minibatches=1,
    num_epochs=1,
    device="cpu",
    progress_bar=False,
    checkpoint_interval=0,
    torch_threads=1,
)


def trainer(num_worlds: int = 1) -> PPOTrainer:
    torch.manual_seed(3)
    env = lane_env(num_worlds=num_worlds, seed=11, episode_length=1.5)
    model = DeepSetsModel(env.layout, input_size=8, hidden_size=8, lstm_size=8)
    return PPOTrainer(env, model, PPOConfig(**CFG), None)


def test_format1_checkpoint_continues_as_it_did():
    payload = ckpt.load(DATA / "ckpt_format1.pt")
    assert payload["format_version"] == 1 and "buffers" in payload["env"]
    t = trainer()
    t.load(DATA / "ckpt_format1.pt")
    env, expected = t.env, np.load(DATA / "ckpt_format1_next.npz")
    rng = np.random.default_rng(7)
    for k in range(24):
        a = np.stack([rng.integers(0, 7, env.num_agents), rng.integers(0, 13, env.num_agents)], 1)
        env.step(a)
        np.testing.assert_array_equal(env.observations, expected["observations"][k], err_msg=f"step {k}")
        np.testing.assert_array_equal(env.rewards, expected["rewards"][k], err_msg=f"step {k}")
        np.testing.assert_array_equal(env.masks, expected["masks"][k], err_msg=f"step {k}")


def test_format1_checkpoint_into_another_configuration_says_why():
    t = trainer(num_worlds=2)
    with pytest.raises(ValueError, match="1 world generators, this env 2: expected the same num_worlds"):
        t.load(DATA / "ckpt_format1.pt")


def format1_env_entry(env) -> dict[str, object]:
    """The env entry format 1 wrote (the former `checkpoint.env_state`)."""
    return {
        "buffers": {k: v.copy() for k, v in env.buffers.items()},
        "extra_terms": env.extra_terms.copy(),
        "reward_mask": env.reward_mask.copy(),
        "world_rngs": [g.bit_generator.state for g in env._world_rngs],
        "py": {
            "_seed": env._seed,
            "_pending_first": env._pending_first,
            "episode_stats": list(env.episode_stats),
        },
    }


@pytest.mark.parametrize("reset_first", [False, True])
def test_format1_env_entry_with_pending_scenario_or_stats(reset_first):
    a, b = (
        lane_env(num_worlds=2, seed=1, episode_length=0.5),
        lane_env(num_worlds=2, seed=2, episode_length=0.5),
    )
    acts = np.zeros((8, a.num_agents, 2), dtype=np.int64)
    if reset_first:
        a.reset()
        for x in acts:
            a.step(x)
        assert a.episode_stats  # 0.5 s episodes ended: unpopped records travel too
    else:
        assert a._pending_first is not None
    ckpt.load_env_state(b, format1_env_entry(a))
    assert b.pop_episode_stats() == a.pop_episode_stats()
    if not reset_first:
        a.reset()
        b.reset()
    for x in acts:
        a.step(x)
        b.step(x)
        np.testing.assert_array_equal(a.observations, b.observations)
        np.testing.assert_array_equal(a.rewards, b.rewards)


def test_observation_width_is_read_from_both_formats():
    from selfplaydrive.policies import trained_obs_dim

    old = ckpt.load(DATA / "ckpt_format1.pt")
    env = lane_env(num_worlds=1, seed=0, episode_length=1.5)
    assert trained_obs_dim(old) == env.layout.obs_dim
    assert trained_obs_dim({"env": env.get_state()}) == env.layout.obs_dim
    assert trained_obs_dim({"model": {}}) is None
