"""`PPOConfig.update_threads`: each minibatch's slots cut into parts whose forward and backward
run on model replicas in pool threads (selfplaydrive/trainers/ppo/parallel.py). The parts'
gradients add up to the minibatch's, so the update is the one-thread update up to float
rounding, and a seed gives the same run every time."""

from __future__ import annotations

import pytest
import torch
from ppo_helpers import assert_same_run
from ppo_helpers import resume_trainer as make_trainer

from selfplaydrive.errors import ConfigError
from selfplaydrive.trainers import PPOConfig
from selfplaydrive.trainers.ppo import checkpoint as ckpt


def trainer(run_dir, **overrides):
    torch.set_num_threads(1)  # the same initial weights in every trainer of the process
    return make_trainer(run_dir, 0, **overrides)


def gradients(t) -> list[torch.Tensor]:
    return [p.grad.clone() for p in t.model.parameters()]


@pytest.mark.parametrize("threads", [2, 3])
def test_the_parts_gradient_is_the_minibatchs_gradient(tmp_path, threads):
    t = trainer(tmp_path, update_threads=threads)
    t.train(1)  # a rollout with episode starts, terminations and idle slots
    slots = torch.arange(t.num_slots)
    info_whole = t.minibatch_step(slots, 1)
    whole = gradients(t)
    info_parts = t.minibatch_step(slots, threads)
    parts = gradients(t)
    assert len(t._parallel.replicas) == threads - 1
    for g, h in zip(whole, parts, strict=True):
        torch.testing.assert_close(h, g, rtol=1e-5, atol=1e-7)
    assert any(float(g.abs().sum()) > 0 for g in whole)
    for k in info_whole:
        torch.testing.assert_close(info_parts[k], info_whole[k], rtol=1e-5, atol=1e-7)
    # the replicas' gradients were handed over and cleared
    assert all(p.grad is None for r in t._parallel.replicas for p in r.parameters())


def test_runs_repeat_bit_for_bit_and_follow_the_one_thread_run(tmp_path):
    a = trainer(tmp_path / "a", update_threads=2)
    a.train(3)
    b = trainer(tmp_path / "b", update_threads=2)
    b.train(3)
    assert_same_run(a, b)
    one = trainer(tmp_path / "one", update_threads=1)
    one.train(1)
    two = trainer(tmp_path / "two", update_threads=2)
    two.train(1)
    for (name, p), q in zip(one.model.state_dict().items(), two.model.state_dict().values(), strict=True):
        torch.testing.assert_close(q, p, rtol=1e-4, atol=1e-6, msg=name)


def test_with_overlapped_collection_runs_repeat_and_resume_exactly(tmp_path):
    a = trainer(tmp_path / "a", update_threads=2, overlap_collection=True, keep_checkpoints=10)
    a.train(4)
    b = trainer(tmp_path / "b", update_threads=2, overlap_collection=True, keep_checkpoints=10)
    b.train(4)
    assert_same_run(a, b)
    c = trainer(tmp_path / "c", update_threads=2, overlap_collection=True, keep_checkpoints=10)
    c.load(tmp_path / "a" / "checkpoints" / ckpt.checkpoint_name(2))
    c.train(2)
    assert_same_run(a, c)


def test_a_parts_exception_is_raised_in_the_caller(tmp_path):
    t = trainer(tmp_path, update_threads=2)
    t.train(1)
    replica = t._parallel.replicas[0]

    def broken(*args, **kwargs):
        raise RuntimeError("part failed")

    replica.forward_sequence = broken
    with pytest.raises(RuntimeError, match="part failed"):
        t.minibatch_step(torch.arange(t.num_slots), 2)


@pytest.mark.parametrize("bad", [0, -1, 1.5, True])
def test_update_threads_is_validated(bad):
    with pytest.raises(ConfigError, match=r"PPOConfig.update_threads = .*expected an int >= 1"):
        PPOConfig(update_threads=bad)
