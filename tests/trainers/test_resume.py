"""Exact resume: N updates, checkpoint, M more == fresh objects loading the checkpoint, M more
(bit for bit on the CPU), including the env's state, recurrent state and RNGs (issue item 4)."""

from __future__ import annotations

import shutil

import pytest
import torch
from ppo_helpers import RESUME_CFG as CFG
from ppo_helpers import assert_same_run, lane_env
from ppo_helpers import resume_trainer as make_trainer

from selfplaydrive.errors import CheckpointError, ConfigError
from selfplaydrive.models import DeepSetsModel
from selfplaydrive.trainers import PPOConfig, PPOTrainer
from selfplaydrive.trainers.ppo import checkpoint as ckpt


@pytest.mark.parametrize("norm_returns", [False, True])
def test_resume_is_bit_identical(tmp_path, norm_returns):
    a = make_trainer(tmp_path / "a", 0, norm_returns=norm_returns)
    a.train(2)  # autoresets, truncations and terminations happen within these rollouts
    path = ckpt.latest(tmp_path / "a" / "checkpoints")
    assert path is not None and path.name == ckpt.checkpoint_name(2)
    path = shutil.copy(path, tmp_path / "after_2.pt")  # the next periodic save prunes it
    a.train(2)
    b = make_trainer(tmp_path / "b", 1, norm_returns=norm_returns)
    b.load(path)
    assert b.update_idx == 2
    b.train(2)
    if norm_returns:  # the return scaler's statistics travel in the checkpoint
        sa, sb = a.return_scaler, b.return_scaler
        assert (sa.count, sa.mean, sa.m2) == (sb.count, sb.mean, sb.m2)
        assert torch.equal(sa.running, sb.running)
    assert_same_run(a, b)
    # periodic checkpoints are pruned to keep_checkpoints
    assert [p.name for p in (tmp_path / "a" / "checkpoints").glob("ckpt_*.pt")] == [ckpt.checkpoint_name(4)]


def test_checkpoint_from_another_env_configuration_is_refused(tmp_path):
    a = make_trainer(None, 0)
    a.save(tmp_path / "c.pt")
    torch.manual_seed(0)
    env = lane_env(num_worlds=5, episode_length=1.5)
    model = DeepSetsModel(env.layout, input_size=16, hidden_size=32, lstm_size=32)
    b = PPOTrainer(env, model, PPOConfig(**CFG))
    with pytest.raises(ValueError, match="expected an env built from the same configuration"):
        b.load(tmp_path / "c.pt")
    with pytest.raises(CheckpointError, match="no such file"):
        b.load(tmp_path / "missing.pt")


def test_config_errors_name_key_value_and_expectation():
    with pytest.raises(ConfigError, match=r"PPOConfig.gamma = 1.5: expected a number in \[0, 1\]"):
        PPOConfig(gamma=1.5)
    with pytest.raises(ConfigError, match=r"PPOConfig.rollout_length = 0: expected an int >= 1"):
        PPOConfig(rollout_length=0)
    with pytest.raises(ConfigError, match="precision = 'fp16': expected one of"):
        PPOConfig(precision="fp16")
    with pytest.raises(ConfigError, match=r"unknown key\(s\) \['lr'\]"):
        PPOConfig.from_dict({"lr": 1e-3})


def test_train_run_writes_the_run_folder_and_resumes_exactly(tmp_path, capsys):
    import json

    from selfplaydrive.trainers import train_run

    cfg = dict(CFG, total_steps=3 * 12 * 12, eval_episodes=4, eval_max_steps=200)
    torch.manual_seed(0)
    env = lane_env(num_worlds=3, episode_length=1.5)
    model = DeepSetsModel(env.layout, input_size=16, hidden_size=32, lstm_size=32)
    out = train_run(env, model, cfg, tmp_path / "run")
    run = tmp_path / "run"
    assert out["updates"] == 3 and out["eval"]["episodes"] >= 4
    assert json.loads((run / "config.json").read_text())["rollout_length"] == 12
    info = json.loads((run / "run_info.json").read_text())
    assert info["agent_slots"] == 12 and info["model"] == "DeepSetsModel" and info["total_updates"] == 3
    saved = json.loads((run / "eval.json").read_text())
    assert 0.0 <= saved["waypoint_completion"] <= 1.0 and "offroad_rate" in saved and "return_mean" in saved
    assert "evaluation: " in capsys.readouterr().out
    assert list((run / "tb").glob("events.out.tfevents.*"))
    assert (run / "checkpoints" / "final.pt").is_file()
    # resume from the periodic checkpoint after update 2: the 3rd update is replayed exactly
    torch.manual_seed(5)
    env2 = lane_env(num_worlds=3, seed=5, episode_length=1.5)
    model2 = DeepSetsModel(env2.layout, input_size=16, hidden_size=32, lstm_size=32)
    out2 = train_run(env2, model2, dict(cfg, eval_episodes=0), run, resume=True)
    assert out2["updates"] == 3
    for (name, p1), p2 in zip(model.state_dict().items(), model2.state_dict().values(), strict=True):
        assert torch.equal(p1, p2), name
