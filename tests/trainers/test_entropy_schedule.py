"""`PPOConfig.ent_coef_final`: the entropy bonus annealed linearly on the learning rate's
schedule (issue #16 item 2 names the entropy schedule among the main job's settings)."""

from __future__ import annotations

import pytest
import torch
from ppo_helpers import RESUME_CFG
from ppo_helpers import resume_trainer as make_trainer

from selfplaydrive.errors import ConfigError
from selfplaydrive.trainers import PPOConfig


def test_the_weight_falls_linearly_from_ent_coef_towards_the_final_value():
    cfg = PPOConfig(ent_coef=0.01, ent_coef_final=0.002)
    # a share `remaining` of the updates left: 1 at the first update, 1/U at the last
    assert cfg.entropy_weight(1.0) == pytest.approx(0.01)
    assert cfg.entropy_weight(0.5) == pytest.approx(0.006)
    assert cfg.entropy_weight(0.25) == pytest.approx(0.004)
    assert PPOConfig(ent_coef=0.01).entropy_weight(0.25) == 0.01  # None: constant


@pytest.mark.parametrize("bad", [-0.1, float("nan"), float("inf"), "0.1", True])
def test_a_bad_final_weight_is_refused_by_name(bad):
    with pytest.raises(ConfigError, match=r"PPOConfig.ent_coef_final = .*expected None or a finite number"):
        PPOConfig(ent_coef_final=bad)


def test_training_uses_and_logs_the_scheduled_weight(tmp_path):
    total_updates = 4
    t = make_trainer(
        tmp_path,
        0,
        ent_coef=0.01,
        ent_coef_final=0.0,
        total_steps=total_updates * 3 * 4 * RESUME_CFG["rollout_length"],  # 3 worlds x 4 slots
    )
    assert t.total_updates == total_updates
    logged = []
    for _ in range(total_updates):
        logged.append(t.train(1)["charts/ent_coef"])
    assert logged == pytest.approx([0.01, 0.0075, 0.005, 0.0025])
    # the loss of the last update's weight: policy - w * entropy + vf * value
    slots = torch.arange(t.num_slots)
    loss, info = t.minibatch_loss(slots)
    expected = info["policy"] - 0.0025 * info["entropy"] + t.config.vf_coef * info["value"]
    assert float(loss.detach()) == pytest.approx(float(expected), rel=1e-6, abs=1e-7)
    assert float(info["entropy"]) > 0.01  # the bonus is not vanishing in the comparison
