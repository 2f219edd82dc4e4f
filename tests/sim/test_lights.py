"""Traffic-light programs as the simulator plays them (paper section 2.2): every state lasts
between 0.5 and 10 s, a change never repeats the state, and the first change comes when the
spawner's initial time left says."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import cross_map, make_scenario
from scipy import stats

from selfplaydrive.scenario.lights import LightSampler
from selfplaydrive.sim import SimParams, VecEnv

DT = 0.1
STEPS = 1500  # 150 s per world, ~28 states per signal group
EPISODE = 200.0  # longer than the rollout: no world resets, so every run is one episode's


class LightSpawner:
    """One parked car and a light program from the project's LightSampler with lights on."""

    def __init__(self) -> None:
        self.lights = LightSampler(all_off_prob=0.0)

    def sample(self, road_map, rng, map_index: int = 0):
        sc = make_scenario([dict(xy=(50, -1.75))], episode_length=EPISODE, map_index=map_index)
        sc.lights_enabled, sc.light_state, sc.light_time_left = self.lights.sample(
            rng, road_map.num_signal_groups, EPISODE
        )
        return sc


@pytest.fixture(scope="module")
def rollout():
    """States (STEPS + 1, W * G) from reset on, and the initial time left (W * G,) [s]."""
    env = VecEnv(cross_map(), LightSpawner(), 128, params=SimParams(dt=DT), seed=3)
    env.reset(3)
    b = env.buffers
    assert b["lights_on"].all() and env.dims.G == 2
    states, time_left = [b["light_state"].copy()], b["light_time"].copy()
    zero = np.tile(np.array([3, 6]), (env.num_agents, 1))
    for _ in range(STEPS):
        env.step(zero)
        states.append(b["light_state"].copy())
    assert np.all(b["step"] == STEPS)  # no world was reset: the runs below are whole
    return np.stack(states), time_left


def changes(column: np.ndarray) -> np.ndarray:
    """Steps at which one group's state differs from the step before."""
    return np.flatnonzero(np.diff(column) != 0) + 1


def test_every_complete_state_lasts_half_to_ten_seconds(rollout):
    states, _ = rollout
    runs = np.concatenate([np.diff(changes(states[:, j])) for j in range(states.shape[1])])
    assert len(runs) > 5000
    # whole steps: 0.5 s is 5 steps, 10 s is 100 (a state drawn d s long lasts round(d / dt))
    assert runs.min() >= 5 and runs.max() <= 100
    # the range is used end to end, about uniformly (mean 5.25 s)
    assert runs.min() <= 6 and runs.max() >= 99
    assert runs.mean() * DT == pytest.approx(5.25, abs=0.15)


def test_a_change_never_repeats_the_state(rollout):
    """Each change moves to one of the 3 other states, about equally often: a redraw of the
    same state would not show as a change here but as a run past 10 s."""
    states, _ = rollout
    counts = np.zeros((4, 4), int)
    for j in range(states.shape[1]):
        at = changes(states[:, j])
        np.add.at(counts, (states[at - 1, j], states[at, j]), 1)
    assert np.all(np.diag(counts) == 0)
    others = counts[~np.eye(4, dtype=bool)].reshape(4, 3)
    np.testing.assert_allclose(others / others.sum(axis=1, keepdims=True), 1 / 3, atol=0.05)


def test_initial_state_lasts_its_time_left(rollout):
    states, time_left = rollout
    first = np.array([changes(states[:, j])[0] for j in range(states.shape[1])])
    # the first change falls on the step nearest the initial time left
    assert np.all(np.abs(first * DT - time_left) <= DT / 2 + 1e-4)
    # and the time left is the spawner's U(0.5, 10) s
    assert time_left.min() >= 0.5 and time_left.max() < 10.0
    assert stats.kstest(time_left, stats.uniform(0.5, 9.5).cdf).pvalue > 1e-3
    # initial states uniform over off, red, yellow, green (section 2.2)
    np.testing.assert_allclose(np.bincount(states[0], minlength=4) / states.shape[1], 0.25, atol=0.08)


def test_lights_identical_at_one_and_two_threads():
    def play(threads: int) -> np.ndarray:
        env = VecEnv(cross_map(), LightSpawner(), 16, num_threads=threads, seed=11)
        env.reset(11)
        zero = np.tile(np.array([3, 6]), (env.num_agents, 1))
        out = []
        for _ in range(300):
            env.step(zero)
            out.append(np.concatenate([env.buffers["light_state"], env.buffers["light_time"].view(np.int8)]))
        return np.stack(out)

    one = play(1)
    assert np.count_nonzero(np.diff(one, axis=0)) > 100  # the lights changed many times
    np.testing.assert_array_equal(one, play(2))
