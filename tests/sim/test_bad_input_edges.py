"""Bad input at the edges of `VecEnv` (issue #14 item 6): counts that are not integers or out
of range, a num_worlds that cannot fit in memory, bad reset seeds, and episode statistics that
are never popped."""

from __future__ import annotations

import time
import warnings

import numpy as np
import pytest
from helpers import FixedSpawner, make_scenario

from selfplaydrive.errors import ConfigError
from selfplaydrive.sim import VecEnv, vec_env
from selfplaydrive.sim.buffers import buffer_bytes


@pytest.fixture
def spawner():
    return FixedSpawner(make_scenario([dict(xy=(0, -2))]))


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"num_worlds": 2.5}, r"num_worlds: expected an integer >= 1, got 2\.5"),
        ({"num_worlds": 0}, r"num_worlds: expected an integer >= 1, got 0"),
        ({"num_worlds": -1}, r"num_worlds: .* got -1"),
        ({"num_worlds": "abc"}, r"num_worlds: .* got 'abc'"),
        ({"num_worlds": True}, r"num_worlds: .* got True"),
        ({"num_worlds": 1, "num_threads": 2.5}, r"num_threads: expected an integer in \[1, \d+\], got 2\.5"),
        ({"num_worlds": 1, "num_threads": -3}, r"num_threads: .* got -3"),
        # libgomp killed the whole process when asked for this many threads
        (
            {"num_worlds": 1, "num_threads": 40_000},
            r"num_threads: expected an integer in \[1, \d+\], got 40000",
        ),
        ({"num_worlds": 1, "seed": -1}, r"seed: expected a non-negative integer, got -1"),
        ({"num_worlds": 1, "seed": 1.5}, r"seed: .* got 1\.5"),
    ],
)
def test_bad_counts_and_seed_are_refused_naming_the_key(straight_map, spawner, kwargs, match):
    with pytest.raises(ConfigError, match=match):
        VecEnv(straight_map, spawner, **kwargs)


def test_thread_cap_is_sane():
    assert 64 <= vec_env.MAX_THREADS <= max(64, 4 * 4096)


def test_integral_float_counts_are_accepted(straight_map, spawner):
    env = VecEnv(straight_map, spawner, 2.0, num_threads=np.int64(2))
    assert env.num_worlds == 2 and isinstance(env.num_worlds, int) and env.num_threads == 2


@pytest.mark.parametrize("seed", [-1, 1.5, "a", True])
def test_reset_seed_errors_name_seed(straight_map, spawner, seed):
    env = VecEnv(straight_map, spawner, 1)
    with pytest.raises(ConfigError, match=r"^seed: expected a non-negative integer, got "):
        env.reset(seed=seed)
    env.reset(seed=np.int64(3))  # numpy integers are fine
    assert env._seed == 3


def test_buffer_bytes_match_the_allocation(straight_map, spawner):
    env = VecEnv(straight_map, spawner, 3)
    assert buffer_bytes(env.dims) == sum(a.nbytes for a in env.buffers.values())


def test_too_many_worlds_refused_up_front_with_the_memory_needed(straight_map, spawner, monkeypatch):
    monkeypatch.setattr(vec_env, "_available_memory", lambda: 8 * 10**9)  # an 8 GB machine
    t0 = time.perf_counter()
    with pytest.raises(ConfigError) as err:
        VecEnv(straight_map, spawner, 10**6)
    # before: a million generators were made, then the allocation ran out of memory
    assert time.perf_counter() - t0 < 5.0
    msg = str(err.value)
    per_world = buffer_bytes(VecEnv(straight_map, spawner, 1).dims)
    assert msg.startswith("num_worlds=1000000: the simulator buffers need ")
    assert f"{per_world * 10**6 / 1e9:,.1f} GB" in msg and f"{per_world / 1e6:.2f} MB per world" in msg
    assert "8.0 GB of memory available" in msg and f"num_worlds <= {8 * 10**9 // per_world}" in msg


def test_worlds_that_fit_are_built_as_before(straight_map, spawner):
    # the generators are now made after the memory check: same seeds, same rollout
    env = VecEnv(straight_map, spawner, 3, seed=7)
    ref = [np.random.default_rng(int(s)) for s in np.random.default_rng(7).integers(0, 2**63 - 1, size=3)]
    for got, want in zip(env._world_rngs[1:], ref[1:], strict=True):
        assert got.integers(0, 2**62) == want.integers(0, 2**62)


def _ending_env(straight_map, worlds: int) -> VecEnv:
    # one agent driving off the road: every world ends (and is recorded) at every step
    sc = make_scenario([dict(xy=(0, -3.2), speed=5.0, coeffs=dict(offroad=0.9))], episode_length=10.0)
    env = VecEnv(straight_map, FixedSpawner(sc), worlds)
    env.reset(0)
    return env


def test_unpopped_episode_stats_are_capped_with_one_warning(straight_map, monkeypatch):
    monkeypatch.setattr(vec_env, "MAX_EPISODE_STATS", 5)
    env = _ending_env(straight_map, 3)
    acts = np.tile(np.array([3, 6]), (env.num_agents, 1))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(4):  # 12 episodes end
            env.step(acts)
    capped = [w for w in caught if "pop_episode_stats" in str(w.message)]
    assert len(capped) == 1 and "at most 5" in str(capped[0].message)
    assert len(env.episode_stats) == 5 and env.dropped_episode_stats == 7
    stats = env.pop_episode_stats()
    assert [s["world"] for s in stats] == [1, 2, 0, 1, 2]  # the newest are kept, in order
    assert env.pop_episode_stats() == []


def test_popped_episode_stats_are_never_dropped(straight_map, monkeypatch):
    monkeypatch.setattr(vec_env, "MAX_EPISODE_STATS", 5)
    env = _ending_env(straight_map, 2)
    acts = np.tile(np.array([3, 6]), (env.num_agents, 1))
    total = 0
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no cap warning while the caller pops
        for _ in range(10):
            env.step(acts)
            total += len(env.pop_episode_stats())
    assert total == 20 and env.dropped_episode_stats == 0
