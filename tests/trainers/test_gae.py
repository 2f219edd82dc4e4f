"""GAE against hand-computed values: truncation bootstraps V(final obs), termination 0,
padded slots get nothing (issue item 3)."""

from __future__ import annotations

import pytest
import torch

from selfplaydrive.trainers.ppo.advantage import compute_gae

GAMMA, LAM = 0.9, 0.8  # gamma * lambda = 0.72


def test_three_steps_with_truncation_termination_and_padding():
    # slot 0: truncated at t=1 (V(final obs) = 4), a new episode at t=2; V(s_3) = 2
    # slot 1: terminated at t=1 (its final value 7 must be ignored), slot removed at t=2
    # slot 2: padded at t=0 (garbage reward/value), its episode starts at t=1
    rewards = torch.tensor([[1.0, 1.0, 5.0], [2.0, -1.0, 1.0], [3.0, 0.0, 1.0]])
    values = torch.tensor([[0.5, 0.2, 3.0], [1.0, 0.4, 1.0], [1.5, 9.0, 1.0]])
    active = torch.tensor([[1, 1, 0], [1, 1, 1], [1, 0, 1]], dtype=torch.bool)
    terminated = torch.tensor([[0, 0, 0], [0, 1, 0], [0, 0, 0]], dtype=torch.bool)
    truncated = torch.tensor([[0, 0, 0], [1, 0, 0], [0, 0, 0]], dtype=torch.bool)
    final_values = torch.tensor([[0.0, 0.0, 0.0], [4.0, 7.0, 0.0], [0.0, 0.0, 0.0]])
    next_value = torch.tensor([2.0, 5.0, 1.0])
    adv, ret = compute_gae(
        rewards, values, next_value, active, terminated, truncated, final_values, GAMMA, LAM
    )
    # slot 0: d2 = 3 + .9*2 - 1.5 = 3.3;  d1 = 2 + .9*4 - 1 = 4.6 (cut: episode ended);
    #         d0 = 1 + .9*1 - .5 = 1.4, A0 = 1.4 + .72*4.6 = 4.712
    # slot 1: t=2 padded -> 0;  d1 = -1 + 0 - .4 = -1.4;  d0 = 1 + .9*.4 - .2 = 1.16,
    #         A0 = 1.16 + .72*(-1.4) = 0.152
    # slot 2: d2 = 1 + .9*1 - 1 = 0.9;  d1 = 0.9, A1 = 0.9 + .72*.9 = 1.548;  t=0 padded -> 0
    expected_adv = torch.tensor([[4.712, 0.152, 0.0], [4.6, -1.4, 1.548], [3.3, 0.0, 0.9]])
    expected_ret = torch.tensor([[5.212, 0.352, 0.0], [5.6, -1.0, 2.548], [4.8, 0.0, 1.9]])
    torch.testing.assert_close(adv, expected_adv, rtol=0, atol=1e-5)
    torch.testing.assert_close(ret, expected_ret, rtol=0, atol=1e-5)


def test_termination_wins_over_truncation_and_lambda_one_is_monte_carlo():
    rewards = torch.tensor([[1.0], [1.0]])
    values = torch.tensor([[0.0], [0.0]])
    ones = torch.ones(2, 1, dtype=torch.bool)
    both = torch.tensor([[False], [True]])
    adv, _ = compute_gae(
        rewards, values, torch.tensor([10.0]), ones, both, both, torch.tensor([[0.0], [50.0]]), 0.5, 1.0
    )
    # terminated at t=1 (truncation flag ignored): A1 = 1, A0 = 1 + 0.5 * 1 = 1.5 (discounted sum)
    torch.testing.assert_close(adv, torch.tensor([[1.5], [1.0]]))


def test_shape_mismatch_is_named():
    v = torch.zeros(3, 2)
    with pytest.raises(ValueError, match=r"next_value: expected shape \(2,\)"):
        compute_gae(v, v, torch.zeros(3), v.bool(), v.bool(), v.bool(), v, 0.9, 0.9)
    with pytest.raises(ValueError, match="rewards: expected shape"):
        compute_gae(torch.zeros(2, 2), v, torch.zeros(2), v.bool(), v.bool(), v.bool(), v, 0.9, 0.9)


def test_trainer_bootstraps_truncated_agents_from_final_observation_value():
    """In a real rollout, truncated agents get V(final obs) (not the autoreset's new first
    observation), terminated agents 0, and GAE uses exactly that value."""
    import numpy as np
    from ppo_helpers import SpeedValueModel, lane_env

    from selfplaydrive.trainers import PPOConfig, PPOTrainer

    env = lane_env(num_worlds=8, episode_length=1.5)  # 15 steps: truncations inside the rollout
    cfg = PPOConfig(rollout_length=40, device="cpu", progress_bar=False, gamma=GAMMA, gae_lambda=LAM)
    trainer = PPOTrainer(env, SpeedValueModel(), cfg)
    finals, step = [], env.step

    def recording_step(actions):
        step(actions)
        finals.append(env.final_observations[:, SpeedValueModel.speed_col].copy())

    env.step = recording_step
    trainer.collect()
    trainer.compute_advantages()
    s = trainer.storage
    n_trunc, n_term = int(s.truncated.sum()), int(s.terminated.sum())
    assert n_trunc >= 16 and n_term >= 1, (n_trunc, n_term)  # both kinds of ending happened
    for t in range(cfg.rollout_length):
        trunc = s.truncated[t].numpy()
        expected = np.where(trunc, 10.0 * finals[t], 0.0)
        np.testing.assert_allclose(s.final_values[t].numpy(), expected, rtol=1e-6)
        # the new episode's first observation would give another value: the test can fail
        nxt = s.values[t + 1].numpy() if t + 1 < cfg.rollout_length else None
        if nxt is not None and trunc.any():
            assert not np.allclose(nxt[trunc], expected[trunc])
        ended = trunc | s.terminated[t].numpy()
        delta = s.rewards[t] + GAMMA * s.final_values[t] - s.values[t]
        np.testing.assert_allclose(s.advantages[t].numpy()[ended], delta.numpy()[ended], rtol=1e-5, atol=1e-6)
