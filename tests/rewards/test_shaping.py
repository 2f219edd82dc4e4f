"""The `conflict` shaping term (issue #16 item 2): hand-computed on a straight two-lane road,
equal to its NumPy reference on random rollouts, the same at one and two threads, off by
default and selectable by name with its parameters."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from selfplaydrive.eval.suites.base import FixedScenarioSpawner, blank_scenario, put_agent
from selfplaydrive.maps.compile import compile_map
from selfplaydrive.maps.elements import LaneElement, MapElements, PolylineElement
from selfplaydrive.maps.loader import load_map
from selfplaydrive.rewards import TERM_NAMES, LinearReward, get_term
from selfplaydrive.scenario.spawner import PaperSpawner
from selfplaydrive.sim import VecEnv
from selfplaydrive.sim.actions import ContinuousActions
from selfplaydrive.testing import shaping_terms

Y0, Y1 = -1.75, 1.75  # [m] centerlines of the eastbound and the westbound lane
X0 = -100.0  # [m] the map is compiled centred on its bounds


@pytest.fixture(scope="module")
def road():
    lanes = [
        LaneElement(np.array([[X0, Y0], [200.0 + X0, Y0]]), 3.5, 14.0, source_id="east"),
        LaneElement(np.array([[200.0 + X0, Y1], [X0, Y1]]), 3.5, 14.0, source_id="west"),
    ]
    edges = [PolylineElement(np.array([[X0, s], [200.0 + X0, s]])) for s in (-3.5, 3.5)]
    return compile_map(MapElements(name="two_lanes", source=__file__, lanes=lanes, road_edges=edges))


def drive(road, cars, steps=3, weight=1.0, args=None):
    """Per-step `conflict` column (steps, cars) of cars (x, y, heading, speed; 4.5 x 2.0 m)
    driven straight at constant speed."""
    sc = blank_scenario(road, 0, np.array([0.0, 0.0]), 6.0)
    for k, (x, y, h, v) in enumerate(cars):
        lane = 0 if h == 0.0 else 1
        put_agent(sc, k, np.array([x + X0, y]), h, v, (4.5, 2.0), lane, np.array([[x + X0, y]]))
    spec = weight if args is None else {"weight": weight, "args": list(args)}
    reward = LinearReward({**dict.fromkeys(TERM_NAMES, 1.0), "conflict": spec})
    env = VecEnv(road, FixedScenarioSpawner([sc]), 1, actions=ContinuousActions(), reward=reward)
    env.reset(0)
    col = env.term_names.index("conflict")
    out = []
    for _ in range(steps):
        env.step(np.zeros((env.num_agents, 2), np.float32))
        out.append(env.reward_terms[: len(cars), col].copy())
    return np.array(out)


def test_head_on_same_lane_adjacent_lane_and_parted_cars(road):
    # 10 m/s towards each other in one lane, 20 m apart: after the first step (0.1 s) 18 m
    # apart, closing at 20 m/s, so the closest approach (0 m) is 0.9 s ahead: -(1 - 0.9 / 2)
    head_on = drive(road, [(20.0, Y0, 0.0, 10.0), (40.0, Y0, np.pi, 10.0)])
    np.testing.assert_allclose(head_on[0], [-0.55, -0.55], atol=1e-5)
    np.testing.assert_allclose(head_on[1], [-0.6, -0.6], atol=1e-5)  # 16 m: 0.8 s
    # the same in the adjacent lane: 3.5 m apart sideways at the closest approach, farther than
    # half the two widths plus the margin (1 + 1 + 0.5 m): no conflict
    assert not drive(road, [(20.0, Y0, 0.0, 10.0), (40.0, Y1, np.pi, 10.0)]).any()
    # moving apart: the closest approach is now (t = 0), 20 m away
    assert not drive(road, [(20.0, Y0, np.pi, 10.0), (40.0, Y0, 0.0, 10.0)]).any()
    # a 3 s horizon sees farther: 56 m apart (54 m after a step) is 2.7 s, -(1 - 2.7 / 3)
    far = drive(road, [(20.0, Y0, 0.0, 10.0), (76.0, Y0, np.pi, 10.0)], args=(3.0, 0.5))
    np.testing.assert_allclose(far[0], [-0.1, -0.1], atol=1e-5)
    assert not drive(road, [(20.0, Y0, 0.0, 10.0), (76.0, Y0, np.pi, 10.0)], steps=1).any()  # T = 2 s
    # the column is weighted like any other
    weighted = drive(road, [(20.0, Y0, 0.0, 10.0), (40.0, Y0, np.pi, 10.0)], weight=0.05)
    np.testing.assert_allclose(weighted[0], [-0.0275] * 2, atol=1e-6)


def test_catching_up_in_one_lane(road):
    # 12 m/s behind a car at 2 m/s, 30 m apart: after a step 29 m, closing at 10 m/s, 2.9 s > T
    assert not drive(road, [(20.0, Y0, 0.0, 12.0), (50.0, Y0, 0.0, 2.0)], steps=1).any()
    # 20 m apart -> 19 m after a step: 1.9 s: -(1 - 0.95) for both cars
    np.testing.assert_allclose(
        drive(road, [(20.0, Y0, 0.0, 12.0), (40.0, Y0, 0.0, 2.0)], steps=1)[0], [-0.05, -0.05], atol=1e-5
    )


def rollout(maps, steps, threads=1, seed=3, check=True):
    env = VecEnv(
        maps,
        PaperSpawner(num_agents=16),
        4,
        seed=seed,
        num_threads=threads,
        reward=LinearReward({**dict.fromkeys(TERM_NAMES, 1.0), "conflict": 1.0}),
    )
    env.reset(seed)
    rng = np.random.default_rng(seed)
    col = env.term_names.index("conflict")
    fired = 0
    for _ in range(steps):
        env.step(np.stack([rng.integers(2, 7, env.num_agents), rng.integers(3, 10, env.num_agents)], axis=1))
        if not check:
            continue
        st = SimpleNamespace(**{**vars(env.state), "active": env.reward_mask.copy()})
        live = np.repeat(env.state.step != 0, env.agents_per_world) & env.reward_mask
        ref = shaping_terms.conflict(st, get_term("conflict").args)
        np.testing.assert_allclose(env.reward_terms[live, col], ref[live], rtol=1e-5, atol=1e-6)
        fired += int(np.count_nonzero(ref[live]))
    return env, fired


def test_kernel_equals_numpy_reference_on_random_rollouts():
    _, fired = rollout(load_map("default"), 60)
    assert fired > 50


def test_deterministic_at_one_and_two_threads():
    town = load_map("default")
    one, _ = rollout(town, 60, threads=1, check=False)
    two, _ = rollout(town, 60, threads=2, check=False)
    for name in ("terms", "term_sum", "reward", "x"):
        np.testing.assert_array_equal(one.buffers[name], two.buffers[name], err_msg=name)


def test_off_by_default_and_listed():
    from selfplaydrive.builder import build_env, compose
    from selfplaydrive.rewards import registered_terms

    assert "conflict" in registered_terms()
    env = build_env(compose("train", ["env.num_worlds=1"]))
    assert "conflict" not in env.term_names
    env = build_env(compose("train", ["env.num_worlds=1", "+reward.terms.conflict=0.05"]))
    assert "conflict" in env.term_names
