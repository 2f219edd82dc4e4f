"""`VecEnv.get_state` / `set_state`: save a rollout, continue it bit for bit (issue #13 item 5)."""

from __future__ import annotations

import numpy as np
import pytest

from selfplaydrive.maps.loader import load_map
from selfplaydrive.scenario.spawner import PaperSpawner
from selfplaydrive.sim import VecEnv
from selfplaydrive.sim.state import STATE_VERSION

WORLDS = 3


def make_env(seed: int = 0, num_threads: int = 1) -> VecEnv:
    # 2 s episodes: autoresets happen within the few dozen steps below
    spawner = PaperSpawner(num_agents=6, episode_lengths=(2.0,))
    return VecEnv(load_map("default"), spawner, WORLDS, seed=seed, num_threads=num_threads)


def actions(env: VecEnv, steps: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, [7, 13], size=(steps, env.num_agents, 2))


def run(env: VecEnv, acts: np.ndarray) -> list[np.ndarray]:
    out = []
    for a in acts:
        env.step(a)
        out += [env.observations.copy(), env.rewards.copy(), env.terminations.copy(), env.masks.copy()]
    return out


def assert_same(a: list[np.ndarray], b: list[np.ndarray]) -> None:
    assert len(a) == len(b)
    for k, (x, y) in enumerate(zip(a, b, strict=True)):
        np.testing.assert_array_equal(x, y, err_msg=f"output {k}")


@pytest.fixture(scope="module")
def stepped():
    env = make_env()
    env.reset(0)
    run(env, actions(env, 17, 1))
    return env


def test_restore_continues_bit_for_bit(stepped):
    env = stepped
    state = env.get_state()
    acts = actions(env, 30, 2)
    first = run(env, acts)
    stats = env.pop_episode_stats()
    assert stats, "no episode ended: the test would not cover autoreset"
    env.set_state(state)
    assert_same(first, run(env, acts))
    assert env.pop_episode_stats() == stats


def test_restore_into_a_fresh_env(stepped):
    state = stepped.get_state()
    acts = actions(stepped, 30, 3)
    first = run(stepped, acts)
    stats = stepped.pop_episode_stats()
    fresh = make_env(seed=5, num_threads=2)  # another seed and thread count: the state decides
    fresh.set_state(state)
    assert_same(first, run(fresh, acts))
    assert fresh.pop_episode_stats() == stats


def test_state_is_plain_and_survives_npz(stepped, tmp_path):
    state = stepped.get_state()
    assert state["version"] == STATE_VERSION
    for key, value in state.items():
        assert isinstance(value, (np.ndarray, int, float, bool)), key
    np.savez(tmp_path / "s.npz", **state)
    acts = actions(stepped, 25, 4)
    first = run(stepped, acts)
    fresh = make_env()
    fresh.set_state(dict(np.load(tmp_path / "s.npz")))
    assert_same(first, run(fresh, acts))


def test_unpopped_episode_stats_and_seed_are_kept():
    env = make_env(seed=3)
    env.reset(3)
    run(env, actions(env, 25, 5))
    assert env.episode_stats
    fresh = make_env(seed=0)
    fresh.set_state(env.get_state())
    assert fresh.pop_episode_stats() == env.pop_episode_stats()
    env.reset()  # continues from the saved seed
    fresh.reset()
    assert_same(run(env, actions(env, 5, 6)), run(fresh, actions(env, 5, 6)))


def test_state_before_the_first_reset():
    env = make_env(seed=4)
    state = env.get_state()
    assert state["reset_pending"] and "pending.agent_xy" in state
    fresh = make_env(seed=9)
    fresh.set_state(state)
    acts = actions(env, 10, 7)
    env.reset()
    fresh.reset()
    np.testing.assert_array_equal(env.observations, fresh.observations)
    assert_same(run(env, acts), run(fresh, acts))


def test_bad_states_name_the_field(stepped):
    good = stepped.get_state()
    before = stepped.get_state()
    cases = {
        "version": (dict(good, version=99), "'version': 99, this selfplaydrive reads"),
        "shape": (dict(good, **{"buffers.x": good["buffers.x"][:-1]}), "'buffers.x': shape"),
        "dtype": (dict(good, **{"buffers.x": good["buffers.x"].astype(np.float64)}), "'buffers.x'.*float64"),
        "missing": (
            {k: v for k, v in good.items() if k != "rng.pcg64"},
            r"missing field\(s\) \['rng.pcg64'\]",
        ),
        "unknown": (dict(good, extra=1), r"unknown field\(s\) \['extra'\]"),
        "scalar": (dict(good, seed="zero"), "'seed': expected a int"),
        "worlds": (dict(good, num_worlds=5), "'num_worlds': 5, this env has 3"),
        "terms": (
            dict(good, term_names=good["term_names"][::-1].copy()),
            r"'term_names': \['velocity', .*, this env has \['waypoint'",
        ),
        "maps": (dict(good, map_names=np.array(["elsewhere"])), r"'map_names': \['elsewhere'\]"),
    }
    for name, (bad, message) in cases.items():
        with pytest.raises(ValueError, match=message):
            stepped.set_state(bad)
        for key, value in before.items():  # nothing was written before the error
            np.testing.assert_array_equal(stepped.get_state()[key], value, err_msg=f"{name}: {key}")
    with pytest.raises(ValueError, match=r"expected the dict of VecEnv\.get_state"):
        stepped.set_state([1, 2])


class SpeedTerm:
    """A Python reward term (runs after the kernels)."""

    name = "speed_term"

    def __call__(self, state):
        return np.float32(0.01) * state.speed


class SpeedFeature:
    """A Python observation hook (one extra column)."""

    name = "speed_feature"
    dim = 1

    def __call__(self, state):
        return (state.speed / np.float32(40.0)).reshape(-1, 1).astype(np.float32)


def test_restore_with_python_components_external_physics_and_continuous_actions():
    pymunk_model = pytest.importorskip("selfplaydrive.physics").PymunkModel
    pytest.importorskip("pymunk")
    from selfplaydrive.rewards import TERM_NAMES, LinearReward
    from selfplaydrive.sim import ContinuousActions

    def build(seed: int) -> VecEnv:
        return VecEnv(
            load_map("default"),
            PaperSpawner(num_agents=6, episode_lengths=(2.0,)),
            2,
            physics=pymunk_model(),
            actions=ContinuousActions(),
            seed=seed,
            terminated_vehicle="obstacle",
            reward=LinearReward({**dict.fromkeys(TERM_NAMES, 1.0), "speed_term": 0.5}, terms=[SpeedTerm()]),
            obs_hooks=[SpeedFeature()],
        )

    env = build(0)
    env.reset(0)
    rng = np.random.default_rng(8)
    acts = np.stack(
        [rng.uniform(-2, 3, (40, env.num_agents)), rng.uniform(-0.3, 0.3, (40, env.num_agents))], -1
    )
    acts = acts.astype(np.float32)
    run(env, acts[:12])
    state = env.get_state()
    first = run(env, acts[12:])
    fresh = build(1)
    fresh.set_state(state)
    assert_same(first, run(fresh, acts[12:]))
