"""Which world-episodes an evaluation counts (`eval.sampling`): each world's first ones, so
that the episode lengths are sampled as the spawner draws them."""

from __future__ import annotations

import numpy as np
import pytest

from selfplaydrive.builder import make_env
from selfplaydrive.eval.sampling import FirstEpisodes, first_episodes_quota
from selfplaydrive.scenario.spawner import PaperSpawner
from selfplaydrive.trainers.ppo.episodes import EpisodeTracker


def test_quota_spreads_the_episodes_over_the_worlds():
    assert first_episodes_quota(32, 16).tolist() == [2] * 16
    assert first_episodes_quota(5, 4).tolist() == [2, 1, 1, 1]
    assert first_episodes_quota(3, 8).tolist() == [1, 1, 1, 0, 0, 0, 0, 0]
    with pytest.raises(ValueError, match="expected >= 1, got 0"):
        first_episodes_quota(0, 4)


def test_first_episodes_of_each_world_not_the_first_to_finish():
    # world 0 draws 20 s episodes, world 1 40 s ones; in the order they finish:
    finished = [(0, 20.0), (0, 20.0), (1, 40.0), (0, 20.0), (0, 20.0), (1, 40.0)]
    records = [{"world": w, "length_s": length} for w, length in finished]
    first = FirstEpisodes(4, 2)
    first.add(records[:4])
    assert not first.done  # world 1 has finished one of its two
    first.add(records[4:])
    assert first.done
    assert [r["world"] for r in first.kept] == [0, 0, 1, 1]
    assert np.mean([r["length_s"] for r in first.kept]) == 30.0
    # counting the first four to finish would have made the mean episode 25 s long
    assert np.mean([r["length_s"] for r in records[:4]]) == 25.0


def _rollout(episodes, steps: int | None):
    """Random actions in 4 worlds of 6 agents with 0.5 s and 4 s episodes; returns the tracker's
    records, returns and the steps taken (until the quota is met, or `steps`)."""
    spawner = PaperSpawner(num_agents=6, episode_lengths=(0.5, 4.0))
    env = make_env("default", spawner=spawner, num_worlds=4, seed=5)
    tracker = EpisodeTracker(env)
    tracker.count_first(episodes)
    env.reset(seed=5)
    tracker.on_reset()
    rng = np.random.default_rng(0)
    records, returns = [], []
    for t in range(steps or 1000):
        acted = env.masks.copy()
        env.step(rng.integers(0, env.action_space.nvec, size=(env.num_agents, 2)).astype(np.int64))
        tracker.on_step(acted)
        r, g = tracker.pop()
        records += r
        returns += g
        if steps is None and tracker.quota_met:
            return records, returns, t + 1
    return records, returns, steps


def test_tracker_keeps_the_first_episodes_and_only_their_agents_returns():
    records, returns, steps = _rollout(6, None)  # quota [2, 2, 1, 1]
    per_world = {w: [r["episode_index"] for r in records if r["world"] == w] for w in range(4)}
    assert per_world == {0: [0, 1], 1: [0, 1], 2: [0], 3: [0]}
    # every agent of a counted episode ends once in it (a contact or the world's end), and no
    # agent of a later episode is counted
    assert len(returns) == sum(r["num_agents"] for r in records)
    all_records, all_returns, _ = _rollout(None, steps)
    assert len(all_records) > len(records) and len(all_returns) > len(returns)
