"""PPO losses against hand-computed values; masked entries contribute nothing."""

from __future__ import annotations

import math

import pytest
import torch

from selfplaydrive.trainers.ppo.losses import masked_mean, normalize_advantages, policy_loss, value_loss

MASK = torch.tensor([True, True, True, False])


def test_clipped_policy_loss_by_hand():
    old = torch.zeros(4)
    new = torch.log(torch.tensor([1.5, 0.5, 1.1, 9.0])).requires_grad_()
    adv = torch.tensor([2.0, -1.0, 3.0, 100.0])
    loss, info = policy_loss(new, old, adv, MASK, clip_coef=0.2)
    # r=1.5, A=2: max(-3, -2*1.2=-2.4) = -2.4;  r=0.5, A=-1: max(0.5, 0.8) = 0.8;
    # r=1.1, A=3: max(-3.3, -3.3) = -3.3;  the masked entry (r=9, A=100) is ignored
    assert loss.item() == pytest.approx((-2.4 + 0.8 - 3.3) / 3, abs=1e-6)
    assert float(info["clip_fraction"]) == pytest.approx(2 / 3)
    kl = ((0.5 - math.log(1.5)) + (-0.5 - math.log(0.5)) + (0.1 - math.log(1.1))) / 3
    assert float(info["approx_kl"]) == pytest.approx(kl, abs=1e-6)
    loss.backward()
    # clipped entries (0: ratio above 1+eps with A>0; 1: below 1-eps with A<0) and the masked
    # one get no gradient; entry 2 gets -A * r / 3 = -3 * 1.1 / 3
    torch.testing.assert_close(new.grad, torch.tensor([0.0, 0.0, -1.1, 0.0]))


def test_value_loss_clipped_and_unclipped_by_hand():
    new = torch.tensor([1.0, 2.0, 0.0, 50.0])
    old = torch.tensor([0.5, 2.5, 0.1, 0.0])
    ret = torch.tensor([2.0, 1.0, 0.05, 0.0])
    # unclipped squared errors 1, 1, 0.0025 -> 0.5 * 2.0025 / 3
    assert float(value_loss(new, old, ret, MASK, False, 0.2)) == pytest.approx(0.5 * 2.0025 / 3)
    # moved values 0.7, 2.3, 0.0 -> errors 1.69, 1.69, 0.0025 (max with unclipped)
    assert float(value_loss(new, old, ret, MASK, True, 0.2)) == pytest.approx(0.5 * 3.3825 / 3)


def test_masked_mean_and_advantage_normalisation():
    x = torch.tensor([1.0, 2.0, 3.0, 100.0])
    assert float(masked_mean(x, MASK)) == pytest.approx(2.0)
    assert float(masked_mean(x, torch.zeros(4, dtype=torch.bool))) == 0.0
    s = math.sqrt(2 / 3)  # population std of 1, 2, 3
    expected = torch.tensor([-1 / s, 0.0, 1 / s, 0.0])
    torch.testing.assert_close(normalize_advantages(x, MASK), expected, atol=1e-5, rtol=0)
