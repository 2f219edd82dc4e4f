"""`PPOConfig.overlap_collection`: the next rollout is collected in a second thread during the
update's last epoch, by the weights at its start (selfplaydrive/trainers/ppo/overlap.py). The
schedule is fixed, so runs repeat bit for bit, split `train()` calls equal one call, and a
checkpoint written with a rollout in flight resumes exactly."""

from __future__ import annotations

import copy

import pytest
import torch
from ppo_helpers import assert_same_run
from ppo_helpers import resume_trainer as make_trainer

from selfplaydrive.errors import ConfigError
from selfplaydrive.models.common import log_prob_and_entropy
from selfplaydrive.trainers import PPOConfig
from selfplaydrive.trainers.ppo import checkpoint as ckpt


def overlapped(run_dir, init_seed=0, **overrides):
    # the trainer sets one thread after the model is built, and the initialisation's QR gives
    # other bits on another thread count: set it first, so that the first run in a process
    # starts from the same weights as later ones
    torch.set_num_threads(1)
    return make_trainer(run_dir, init_seed, overlap_collection=True, keep_checkpoints=10, **overrides)


def test_overlapped_runs_repeat_and_split_calls_equal_one_call(tmp_path):
    a = overlapped(tmp_path / "a")
    a.train(4)
    b = overlapped(tmp_path / "b")
    b.train(4)
    assert_same_run(a, b)
    c = overlapped(tmp_path / "c")
    c.train(1)  # the pipeline holds the next rollout between calls
    assert c._pending
    c.train(3)
    assert_same_run(a, c)


def test_a_checkpoint_between_calls_resumes_exactly(tmp_path):
    a = overlapped(tmp_path / "a", total_steps=5 * 3 * 4 * 12)  # 5 updates of 3 worlds x 4 slots x 12 steps
    a.train(2)
    a.save(tmp_path / "between.pt")  # with rollout 3 in hand: saved as the state before it
    a.train(3)
    b = overlapped(tmp_path / "b", init_seed=1, total_steps=5 * 3 * 4 * 12)
    b.load(tmp_path / "between.pt")
    b.train(3)
    assert_same_run(a, b)
    # the last update collects the next rollout too: a larger budget later continues exactly
    assert b.update_idx == b.total_updates and b._pending


def test_resume_from_a_checkpoint_written_with_a_rollout_in_flight(tmp_path):
    a = overlapped(tmp_path / "a")
    a.train(5)  # checkpoints after updates 2 and 4, each while rollout 3 (5) was collected
    path = tmp_path / "a" / "checkpoints" / ckpt.checkpoint_name(2)
    payload = ckpt.load(path, map_location="cpu")
    assert payload["pending_rollout"] is True
    b = overlapped(tmp_path / "b", init_seed=1)  # another init: the load must override it
    b.load(path)
    b.train(3)
    assert_same_run(a, b)


def test_the_next_rollout_is_collected_by_the_weights_at_the_last_epochs_start(tmp_path):
    """With 2 epochs x 2 minibatches, rollout k+1 is collected by the weights after the first
    2 optimizer steps of update k: its stored log-probabilities are those weights', not those
    at the start of update k or of update k+1."""
    t = overlapped(tmp_path / "t")
    steps, actor_weights, seen = [], [], []
    step, load, update = t.optimizer.step, t.actor.load_state_dict, t.update

    def counting_step(*args, **kwargs):
        steps.append(1)
        return step(*args, **kwargs)

    def recording_load(weights):
        actor_weights.append((len(steps), copy.deepcopy(dict(weights))))
        return load(weights)

    def recording_update(*args, **kwargs):
        s = t.storage
        weights = copy.deepcopy(t.model.state_dict())
        rollout = (s.obs, s.actions, s.logprobs, s.active, s.episode_start)
        seen.append((weights, *(x.clone() for x in rollout), tuple(x.clone() for x in s.initial_state)))
        return update(*args, **kwargs)

    t.optimizer.step, t.actor.load_state_dict, t.update = counting_step, recording_load, recording_update
    t.train(3)
    # the initial weights (first rollout), then after 2, 6 and 10 optimizer steps (updates 0-2:
    # the pipeline collects the fourth rollout before the call returns)
    assert [n for n, _ in actor_weights] == [0, 2, 6, 10]
    model = copy.deepcopy(t.model)

    def logprobs_under(weights, k):
        _, obs, actions, _, active, start, init = seen[k]
        model.load_state_dict(weights)
        with torch.no_grad():
            logits, _, _ = model.forward_sequence(obs, init, start)
        lp, _ = log_prob_and_entropy(logits, actions, t.nvec)
        return lp[active]

    for k in (0, 1, 2):
        stored = seen[k][3][seen[k][4]]
        assert len(stored) > 0
        torch.testing.assert_close(logprobs_under(actor_weights[k][1], k), stored, atol=1e-4, rtol=1e-4)
        if k:
            assert (logprobs_under(seen[k][0], k) - stored).abs().max() > 1e-3
            assert (logprobs_under(seen[k - 1][0], k) - stored).abs().max() > 1e-3


def test_a_failing_collection_stops_training_with_its_error(tmp_path):
    t = overlapped(tmp_path / "t")
    step = t.env.step
    calls = []

    def failing_step(actions):
        calls.append(1)
        if len(calls) > 20:  # inside the collector thread (the first rollout has 12 steps)
            raise RuntimeError("simulator failed at step 21")
        return step(actions)

    t.env.step = failing_step
    with pytest.raises(RuntimeError, match="simulator failed at step 21"):
        t.train(3)
    assert t.update_idx == 0


def test_overlap_collection_must_be_a_bool():
    with pytest.raises(ConfigError, match=r"overlap_collection = 'yes': expected true or false"):
        PPOConfig(overlap_collection="yes")


def test_evaluation_draws_as_if_the_rollout_in_hand_were_not_collected(tmp_path):
    """The last update collects the next rollout too (so that an extended run continues
    exactly); evaluations then sample from the generator as it was before that rollout, as a
    trainer resumed from the checkpoint (which collects it again later) does."""
    a = overlapped(tmp_path / "a", total_steps=3 * 3 * 4 * 12)
    a.train()
    assert a._pending
    a.save(tmp_path / "final.pt")
    b = overlapped(tmp_path / "b", init_seed=1, total_steps=3 * 3 * 4 * 12)
    b.load(tmp_path / "final.pt")
    assert not b._pending
    for seed in (5, 6):  # the second evaluation continues the first one's draws
        assert a.evaluate(4, 200, False, seed) == b.evaluate(4, 200, False, seed)


def test_a_checkpoint_with_a_rollout_in_flight_resumes_without_overlap_counting_it_once(tmp_path):
    """Resumed with overlap_collection off, the rollout in flight is collected again by the
    model and counted once: slot-steps stay one rollout per update, also through a checkpoint
    written right after the load, before that rollout was collected again."""
    a = overlapped(tmp_path / "a")
    a.train(2)
    path = tmp_path / "a" / "checkpoints" / ckpt.checkpoint_name(2)
    b = make_trainer(tmp_path / "b", 1, overlap_collection=False)
    b.load(path)
    per_update = b.slots_per_update
    assert (b.update_idx, b.global_step, b.trained_steps) == (2, 3 * per_update, 2 * per_update)
    b.save(tmp_path / "reloaded.pt")  # the rollout is still to be collected again
    c = make_trainer(tmp_path / "c", 2, overlap_collection=False)
    c.load(tmp_path / "reloaded.pt")
    for t in (b, c):
        t.train(2)
        assert (t.update_idx, t.global_step, t.trained_steps) == (4, 4 * per_update, 4 * per_update)
    assert_same_run(b, c)


def test_a_checkpoint_without_an_actor_gives_the_actor_the_models_weights(tmp_path):
    a = make_trainer(tmp_path / "a", 0, overlap_collection=False)
    a.train(2)
    a.save(tmp_path / "plain.pt")
    b = overlapped(tmp_path / "b", init_seed=1)
    b.load(tmp_path / "plain.pt")
    for (name, p), q in zip(b.model.state_dict().items(), b.actor.state_dict().values(), strict=True):
        assert torch.equal(p, q), name
