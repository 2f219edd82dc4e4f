"""Hand-computed checks of the vehicle dynamics (paper section 2.6)."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import FixedSpawner, make_scenario

from selfplaydrive.physics import BicycleModel, FrictionBicycleModel
from selfplaydrive.sim import VecEnv
from selfplaydrive.sim.actions import STEER_DEGREES

ZERO = (3, 6)  # accel 0, steer 0 in the default tables


def run(road_map, agent, steps, action=ZERO, physics=None):
    env = VecEnv(
        road_map,
        FixedSpawner(make_scenario([agent], episode_length=1000.0)),
        1,
        physics=physics or BicycleModel(),
    )
    env.reset(0)
    acts = np.tile(np.asarray(action, np.int64), (env.num_agents, 1))
    track = []
    for _ in range(steps):
        env.step(acts)
        b = env.buffers
        track.append((b["x"][0], b["y"][0], b["speed"][0], b["a_long"][0], b["a_lat"][0]))
    return np.array(track, np.float64)


@pytest.mark.parametrize("model", [BicycleModel(), FrictionBicycleModel()])
def test_constant_speed_moves_20m_in_2s(straight_map, model):
    t = run(straight_map, dict(xy=(-50.0, -2.0), speed=10.0), 20, physics=model)
    assert t[-1, 0] == pytest.approx(-50.0 + 20.0, abs=1e-3)
    assert t[-1, 1] == pytest.approx(-2.0, abs=1e-6)
    assert t[-1, 2] == pytest.approx(10.0)


def fit_radius(xy: np.ndarray) -> float:
    # algebraic circle fit: x^2 + y^2 + D x + E y + F = 0
    A = np.column_stack([xy[:, 0], xy[:, 1], np.ones(len(xy))])
    rhs = -(xy[:, 0] ** 2 + xy[:, 1] ** 2)
    D, E, F = np.linalg.lstsq(A, rhs, rcond=None)[0]
    return float(np.sqrt(D * D / 4 + E * E / 4 - F))


def test_constant_steering_gives_bicycle_radius(straight_map):
    model = BicycleModel()
    k = STEER_DEGREES.index(10.0)
    t = run(straight_map, dict(xy=(0.0, 0.0), speed=5.0), 150, action=(3, k), physics=model)
    expected = model.radius(4.5, np.deg2rad(10.0))
    # hand value: L = 2.7 m, beta = atan(tan(10 deg) / 2) -> R = 1.35 / sin(beta) = 15.37 m
    assert expected == pytest.approx(1.35 / np.sin(np.arctan(np.tan(np.deg2rad(10)) / 2)))
    assert expected == pytest.approx(15.37, abs=0.01)
    assert fit_radius(t[:, :2]) == pytest.approx(expected, rel=5e-3)
    assert t[-1, 4] == pytest.approx(25.0 / expected, rel=1e-3)  # a_lat = v^2 / R


def test_friction_limit_understeers(straight_map):
    k = STEER_DEGREES.index(19.0)
    mu, v = 0.7, 15.0
    agent = dict(xy=(0.0, 0.0), speed=v, hidden=(mu, 1.0, 1.0))
    plain = run(straight_map, agent, 60, action=(3, k), physics=BicycleModel())
    fric = run(straight_map, agent, 60, action=(3, k), physics=FrictionBicycleModel())
    requested = BicycleModel().radius(4.5, np.deg2rad(19.0))  # 7.96 m
    assert fit_radius(plain[:, :2]) == pytest.approx(requested, rel=1e-2)
    # the lateral acceleration is capped at mu g, so the radius becomes v^2 / (mu g) = 32.8 m
    assert fit_radius(fric[:, :2]) == pytest.approx(v * v / (mu * 9.81), rel=1e-2)
    assert np.all(np.abs(fric[:, 4]) <= mu * 9.81 * (1 + 1e-5))


def test_friction_scales_braking_in_a_turn(straight_map):
    k = STEER_DEGREES.index(38.0)
    t = run(
        straight_map,
        dict(xy=(0.0, 0.0), speed=12.0, hidden=(1.0, 1.0, 1.0)),
        1,
        action=(0, k),
        physics=FrictionBicycleModel(),
    )
    assert np.hypot(t[0, 3], t[0, 4]) <= 9.81 * (1 + 1e-4)
    assert -4.0 < t[0, 3] < 0.0  # braking reduced below the requested 4 m/s^2


def test_gains_multiply_actions_and_speed_stays_nonnegative(straight_map):
    t = run(straight_map, dict(xy=(0.0, 0.0), speed=0.0, hidden=(1.0, 1.1, 1.0)), 10, action=(4, 6))
    assert t[-1, 2] == pytest.approx(1.33 * 1.1 * 1.0, rel=1e-5)
    t = run(straight_map, dict(xy=(0.0, 0.0), speed=1.0), 10, action=(0, 6))
    assert t[-1, 2] == 0.0 and np.all(t[:, 2] >= 0.0)
    assert t[0, 3] == pytest.approx(-4.0, rel=1e-5)
    assert t[2, 3] == pytest.approx(-2.0, rel=1e-4)  # 0.2 m/s left, clamped at 0: -2 m/s^2 realised
