"""Reward scaling by the running spread of the discounted return (`PPOConfig.norm_returns`,
trainers/ppo/returns.py): a NumPy reference on random rollouts, hand-computed values, and the
trainer's use of it (scaled GAE inputs, logged scale; exact resume in test_resume.py)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from ppo_helpers import resume_trainer

from selfplaydrive.errors import ConfigError
from selfplaydrive.trainers import PPOConfig
from selfplaydrive.trainers.ppo.returns import ReturnScaler


def reference(rollouts, gamma):
    """Plain loops: per-slot return, restarted at episode starts, kept where inactive; every
    active entry's return pooled; rewards divided by the population std after each rollout."""
    n = rollouts[0][0].shape[1]
    running = np.zeros(n)
    pooled: list[float] = []
    outs = []
    for rewards, active, start in rollouts:
        for t in range(rewards.shape[0]):
            for i in range(n):
                if active[t, i]:
                    base = 0.0 if start[t, i] else running[i]
                    running[i] = gamma * base + rewards[t, i]
                    pooled.append(running[i])
        std = np.sqrt(np.var(pooled) + 1e-8) if len(pooled) >= 2 else 1.0
        outs.append(rewards / std)
    return outs


def random_rollout(rng, t_len=9, n=5):
    active = rng.random((t_len, n)) < 0.7
    start = (rng.random((t_len, n)) < 0.15) & active
    rewards = np.where(active, rng.normal(0.3, 1.5, (t_len, n)), 0.0).astype(np.float32)
    return rewards, active, start


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_scaler_matches_the_numpy_reference_on_random_rollouts(seed):
    rng = np.random.default_rng(seed)
    rollouts = [random_rollout(rng) for _ in range(4)]
    expected = reference(rollouts, gamma=0.9)
    scaler = ReturnScaler(5, 0.9, torch.device("cpu"))
    for (r, a, s), want in zip(rollouts, expected, strict=True):
        got = scaler.scale(torch.from_numpy(r), torch.from_numpy(a), torch.from_numpy(s))
        assert got.dtype == torch.float32
        np.testing.assert_allclose(got.numpy(), want, rtol=1e-5, atol=1e-6)


def test_hand_computed_returns_and_spread():
    # one slot, reward 1 three times, gamma 0.5: returns 1, 1.5, 1.75; mean 17/12;
    # variance ((5/12)^2 + (1/12)^2 + (4/12)^2) / 3 = 42/432; sigma = 0.311805
    scaler = ReturnScaler(1, 0.5, torch.device("cpu"))
    ones = torch.ones(3, 1)
    out = scaler.scale(ones, torch.ones(3, 1, dtype=torch.bool), torch.zeros(3, 1, dtype=torch.bool))
    assert scaler.count == 3 and scaler.mean == pytest.approx(17 / 12)
    assert scaler.std == pytest.approx((42 / 432) ** 0.5, rel=1e-6)
    assert out[0, 0].item() == pytest.approx(1 / 0.3118048, rel=1e-5)
    assert scaler.running.item() == pytest.approx(1.75)


def test_episode_start_restarts_the_return_and_idle_slots_keep_theirs():
    scaler = ReturnScaler(2, 0.5, torch.device("cpu"))
    rewards = torch.tensor([[2.0, 4.0], [2.0, 0.0], [2.0, 0.0]])
    active = torch.tensor([[True, True], [True, False], [True, False]])
    start = torch.tensor([[False, False], [True, False], [False, False]])
    scaler.scale(rewards, active, start)
    # slot 0: 2, then restarted: 2, 3; slot 1: 4, then idle (kept)
    assert scaler.running.tolist() == [3.0, 4.0]
    assert scaler.count == 4 and scaler.mean == pytest.approx((2 + 2 + 3 + 4) / 4)


def test_first_rollout_without_spread_divides_by_one():
    scaler = ReturnScaler(3, 0.99, torch.device("cpu"))
    rewards = torch.tensor([[0.5, 0.0, 0.0]])
    out = scaler.scale(rewards, torch.tensor([[True, False, False]]), torch.zeros(1, 3, dtype=torch.bool))
    assert scaler.count == 1 and scaler.std == 1.0
    assert torch.equal(out, rewards)


def test_trainer_scales_the_rewards_it_feeds_to_gae_and_logs_the_scale(tmp_path):
    trainer = resume_trainer(None, 0, norm_returns=True)
    metrics = trainer.train(1)
    scaler = trainer.return_scaler
    assert scaler is not None and scaler.count == int(trainer.storage.active.sum())
    assert metrics["charts/return_scale"] == pytest.approx(scaler.std)
    assert scaler.std != 1.0
    # the returns GAE produced are consistent with the scaled rewards: for lambda = 1 they would
    # be discounted sums; here check one step's TD identity on a slot that acts twice in a row
    s = trainer.storage
    scaled = s.rewards / scaler.std
    t, i = next(
        (t, i)
        for t in range(s.rollout_length - 1)
        for i in range(s.num_slots)
        if s.active[t, i] and s.active[t + 1, i] and not (s.terminated[t, i] or s.truncated[t, i])
    )
    delta = scaled[t, i] + trainer.config.gamma * s.values[t + 1, i] - s.values[t, i]
    lam = trainer.config.gamma * trainer.config.gae_lambda
    assert s.advantages[t, i].item() == pytest.approx((delta + lam * s.advantages[t + 1, i]).item(), abs=1e-5)


def test_norm_returns_must_be_a_bool():
    with pytest.raises(ConfigError, match=r"PPOConfig\.norm_returns = 'yes': expected true or false"):
        PPOConfig(norm_returns="yes")
