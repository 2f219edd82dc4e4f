"""The shipped checkers (selfplaydrive/testing/checkers.py) pass on the shipped components and
fail, naming the component and the check, on deliberately broken ones."""

from __future__ import annotations

import dataclasses
import random

import numpy as np
import pytest

from selfplaydrive.maps.loader import load_map
from selfplaydrive.rewards import TERM_NAMES, get_term
from selfplaydrive.scenario import PaperSpawner
from selfplaydrive.testing import ComponentCheckError, check_reward_term, check_spawner


@pytest.fixture(scope="module")
def town():
    return load_map("default")


def small_spawner() -> PaperSpawner:
    return PaperSpawner(num_agents=8, num_static=8, num_pedestrians=2, episode_lengths=(2.0,))


# reward terms ------------------------------------------------------------------------------
class SpeedLimit:
    name = "speed_limit"

    def __call__(self, state):
        return np.float32(-0.01) * np.maximum(state.speed - np.float32(14.0), np.float32(0.0))


class NaNTerm(SpeedLimit):
    name = "nan_term"

    def __call__(self, state):
        out = super().__call__(state)
        out[3] = np.nan
        return out


class NoisyTerm(SpeedLimit):
    name = "noisy"

    def __call__(self, state):
        return np.random.default_rng().random(state.speed.shape).astype(np.float32)


class WrongShape(SpeedLimit):
    name = "wrong_shape"

    def __call__(self, state):
        return super().__call__(state)[:-1]


class WritesState(SpeedLimit):
    name = "writes_state"

    def __call__(self, state):
        state.speed[:] = 0.0
        return super().__call__(state)


@pytest.mark.parametrize("name", TERM_NAMES)
def test_shipped_terms_pass(town, name):
    check_reward_term(get_term(name).renamed(f"{name}_copy"), town, small_spawner(), steps=20)


def test_python_term_passes(town):
    check_reward_term(SpeedLimit(), town, small_spawner())


@pytest.mark.parametrize(
    ("term", "message"),
    [
        (NaNTerm(), r"reward term 'nan_term' \(python\).*wrote nan for agent slot 3"),
        (NoisyTerm(), r"reward term 'noisy' \(python\): step 0: nondeterministic: agent slot"),
        (WrongShape(), r"reward term 'wrong_shape' \(python\).*expected an output of shape"),
        (WritesState(), r"reward term 'writes_state' \(python\): step 0: wrote to its input"),
    ],
)
def test_broken_python_terms_fail(town, term, message):
    with pytest.raises(ComponentCheckError, match=message):
        check_reward_term(term, town, small_spawner())


def test_broken_compiled_terms_fail(town):
    numba = pytest.importorskip("numba")
    from selfplaydrive.rewards import KernelTerm
    from selfplaydrive.rewards.numba_abi import SIGNATURE, SIM, f32_ptr, int_field, u8_ptr

    @numba.cfunc(SIGNATURE)
    def brakes_everyone(sim, prm, atlas, args, w, out, stride):
        A = int_field(sim, SIM.A)
        speed, active = f32_ptr(sim, SIM.speed), u8_ptr(sim, SIM.active)
        for a in range(A):
            i = w * A + a
            if active[i]:
                out[a * stride] = np.float32(0.0)
                speed[i] = np.float32(0.0)  # the state is not this term's output

    @numba.cfunc(SIGNATURE)
    def infinite(sim, prm, atlas, args, w, out, stride):
        A = int_field(sim, SIM.A)
        for a in range(A):
            out[a * stride] = np.float32(np.inf)

    term = KernelTerm.from_numba("brakes_everyone", brakes_everyone)
    with pytest.raises(ComponentCheckError, match=r"'brakes_everyone' \(numba\).*wrote outside its column"):
        check_reward_term(term, town, small_spawner())
    with pytest.raises(ComponentCheckError, match=r"'infinite' \(numba\).*wrote inf"):
        check_reward_term(KernelTerm.from_numba("infinite", infinite), town, small_spawner())


def test_not_a_term():
    with pytest.raises(ComponentCheckError, match="expected a KernelTerm or a RewardHook"):
        check_reward_term(object())  # type: ignore[arg-type]


# spawners ----------------------------------------------------------------------------------
class Overlapping(PaperSpawner):
    """Puts agent 1 on top of agent 0."""

    def sample(self, road_map, rng, map_index=0):
        sc = super().sample(road_map, rng, map_index)
        sc.agent_xy[1] = sc.agent_xy[0] + 0.5
        sc.agent_valid[:2] = True
        return sc


class TooManyWaypoints(PaperSpawner):
    def sample(self, road_map, rng, map_index=0):
        sc = super().sample(road_map, rng, map_index)
        sc.num_waypoints[np.flatnonzero(sc.agent_valid)[0]] = sc.waypoints.shape[1] + 1
        return sc


class GlobalRandom(PaperSpawner):
    def sample(self, road_map, rng, map_index=0):
        return super().sample(road_map, np.random.default_rng(np.random.randint(1 << 30)), map_index)


class TouchesGlobal(PaperSpawner):
    def sample(self, road_map, rng, map_index=0):
        random.random()  # same scenario, but another process's draws would shift
        return super().sample(road_map, rng, map_index)


class Counting(PaperSpawner):
    """Keeps a counter between calls: the same generator state gives another scenario."""

    calls = 0

    def sample(self, road_map, rng, map_index=0):
        self.calls += 1
        sc = super().sample(road_map, rng, map_index)
        return dataclasses.replace(sc, episode_length=float(self.calls))


class FloatCounts(PaperSpawner):
    def sample(self, road_map, rng, map_index=0):
        sc = super().sample(road_map, rng, map_index)
        return dataclasses.replace(sc, num_waypoints=sc.num_waypoints.astype(np.int64))


class IgnoresMapIndex(PaperSpawner):
    def sample(self, road_map, rng, map_index=0):
        return super().sample(road_map, rng, 0)


def test_shipped_spawner_passes(town):
    check_spawner(small_spawner(), town)
    check_spawner(PaperSpawner(), town, samples=3, steps=5)  # the paper's sizes


@pytest.mark.parametrize(
    ("spawner", "message"),
    [
        (Overlapping(num_agents=8), r"spawner Overlapping: seed 0: vehicles agent 0 and agent 1 overlap"),
        (
            TooManyWaypoints(num_agents=8),
            r"TooManyWaypoints: seed 0: scenario.num_waypoints: expected",
        ),
        (GlobalRandom(num_agents=8), r"spawner GlobalRandom: not deterministic"),
        (TouchesGlobal(num_agents=8), r"spawner TouchesGlobal: drew from a global generator"),
        (Counting(num_agents=8), r"spawner Counting: not deterministic.*scenario.episode_length"),
        (FloatCounts(num_agents=8), r"spawner FloatCounts: seed 0: scenario.num_waypoints is int64"),
        (IgnoresMapIndex(num_agents=8), r"spawner IgnoresMapIndex: sample\(seed=1, map_index=1\) returned"),
    ],
)
def test_broken_spawners_fail(town, spawner, message):
    with pytest.raises(ComponentCheckError, match=message):
        check_spawner(spawner, town, samples=3, steps=0)


def test_not_a_spawner(town):
    with pytest.raises(ComponentCheckError, match="expected a sample"):
        check_spawner(object(), town)  # type: ignore[arg-type]
