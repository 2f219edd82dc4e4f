"""Events and the eight reward terms on constructed states (paper section 2.3), hand-computed.

straight_map local frame: east lane along +x at y = -2, west lane at y = 1.5, road edges at
y = -3.75 and y = 5.25 (compile_map recentres the map by (100, 2)).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import FixedSpawner, cross_map, make_scenario

from selfplaydrive.physics import BicycleModel
from selfplaydrive.rewards import TERM_NAMES
from selfplaydrive.sim import SimParams, VecEnv

ZERO = (3, 6)


def env_for(road_map, agents, steps=1, action=ZERO, **kw):
    sc_kw = {k: kw.pop(k) for k in ("statics", "peds", "lights") if k in kw}
    env = VecEnv(
        road_map,
        FixedSpawner(make_scenario(agents, episode_length=100.0, **sc_kw)),
        1,
        physics=BicycleModel(),
        **kw,
    )
    env.reset(0)
    acts = np.tile(np.asarray(action, np.int64), (env.num_agents, 1))
    for _ in range(steps):
        env.step(acts)
    return env


def term(env, i, name):
    return float(env.reward_terms[i, TERM_NAMES.index(name)])


def test_head_on_pair_collides_with_speed_scaled_penalty(straight_map):
    a = dict(xy=(-10.0, -2.0), heading=0.0, speed=10.0, coeffs=dict(collision=0.3))
    b = dict(xy=(10.0, -2.0), heading=math.pi, speed=10.0, coeffs=dict(collision=0.8))
    env = env_for(straight_map, [a, b], steps=8)  # gap 20 - 4.5 = 15.5 m closes at 20 m/s: 0.8 s
    assert env.buffers["events"][0] & 1 and env.buffers["events"][1] & 1
    assert term(env, 0, "collision") == pytest.approx(-0.3 * (1 + 0.1 * 10.0))
    # C_collision >= 0.5 terminates, below does not (section 2.3)
    assert env.terminations[1] and not env.terminations[0]
    assert not env.masks[1] and env.masks[0]


def test_no_collision_one_step_earlier(straight_map):
    a = dict(xy=(-10.0, -2.0), speed=10.0)
    b = dict(xy=(10.0, -2.0), heading=math.pi, speed=10.0)
    env = env_for(straight_map, [a, b], steps=7)  # gap left 1.5 m
    assert not env.buffers["events"][0] & 1


@pytest.mark.parametrize("substeps, hit", [(32, True), (1, False)])
def test_fast_small_vehicle_does_not_tunnel_through_thin_box(straight_map, substeps, hit):
    # 1.8 m bicycle at 30 m/s (3 m per step) toward a 0.1 m thin static box across the lane;
    # sampled positions straddle the box (x = 9 and 12 vs box at 10.5): only sub-steps see it
    car = dict(xy=(0.0, -2.0), speed=30.0, length=1.8, width=0.6)
    wall = dict(xy=(10.5, -2.0), heading=math.pi / 2, length=2.0, width=0.1)
    env = env_for(straight_map, [car], steps=4, statics=[wall], params=SimParams(max_substeps=substeps))
    hits = env.pop_episode_stats()  # nothing ended
    assert not hits
    collided = bool(env.buffers["ever"][0] & 1)
    assert collided == hit


def test_road_edge_contact_penalty(straight_map):
    env = env_for(
        straight_map, [dict(xy=(0.0, -3.0), speed=5.0, coeffs=dict(offroad=0.4))]
    )  # box spans y -4..-2
    assert env.buffers["events"][0] & 4
    assert term(env, 0, "offroad") == pytest.approx(-0.4 * (1 + 0.1 * 5.0))
    env = env_for(straight_map, [dict(xy=(0.0, -2.0), speed=5.0)])
    assert not env.buffers["events"][0] & 4 and term(env, 0, "offroad") == 0.0


@pytest.mark.parametrize("state, penalised", [(1, True), (3, False), (2, False)])
def test_red_light_line(state, penalised):
    m = cross_map()  # group 0 line across the east lane at x = -4.5 (cross_map is centred)
    car = dict(xy=(-8.0, -1.75), speed=10.0, coeffs=dict(red_light=0.7))
    env = env_for(m, [car], steps=0, lights=[(state, 50.0), (3, 50.0)])
    red = []
    for _ in range(4):
        env.step(np.tile(np.asarray(ZERO, np.int64), (env.num_agents, 1)))
        red.append(term(env, 0, "red_light"))
    assert bool(env.buffers["ever"][0] & 8) == penalised
    assert any(r == pytest.approx(-0.7) for r in red) == penalised
    assert all(r in (0.0, pytest.approx(-0.7)) for r in red)


def test_waypoint_reward_and_advance(straight_map):
    car = dict(
        xy=(0.0, -2.0), speed=10.0, waypoints=[(2.5, -2.0), (60.0, -2.0)], coeffs=dict(waypoint_radius=2.0)
    )
    env = env_for(straight_map, [car], steps=1)  # centre at 1.0: 1.5 m < 2 m from the first
    assert term(env, 0, "waypoint") == pytest.approx(0.25)
    assert env.buffers["wp_idx"][0] == 1
    env.step(np.tile(np.asarray(ZERO, np.int64), (env.num_agents, 1)))
    assert term(env, 0, "waypoint") == 0.0


def test_comfort_penalty(straight_map):
    env = env_for(straight_map, [dict(xy=(0.0, -2.0), speed=5.0, coeffs=dict(comfort=0.008))], action=(6, 6))
    assert env.buffers["a_long"][0] == pytest.approx(4.0, rel=1e-5)
    assert term(env, 0, "comfort") == pytest.approx(-0.008)
    env = env_for(straight_map, [dict(xy=(0.0, -2.0), speed=5.0)], action=(5, 6))  # 2.67 m/s^2
    assert term(env, 0, "comfort") == 0.0


def test_lane_terms_hand_computed(straight_map):
    # 0.5 m left of the east lane centre: s = -0.5 (+ is right), alpha = 0.1 rad (rotated left)
    c = dict(center=2e-3, center_bias=0.1, align=1e-2)
    env = env_for(straight_map, [dict(xy=(0.0, -1.5), heading=0.1, speed=3.0, coeffs=c)], action=(3, 6))
    b = env.buffers
    s, alpha = float(b["lane_s"][0]), float(b["lane_alpha"][0])
    dy = 3.0 * math.sin(0.1) * 0.1  # moved left during the step
    assert s == pytest.approx(-0.5 - dy, abs=1e-5)
    assert alpha == pytest.approx(0.1, abs=1e-6)
    dev = abs(0.1 - s)
    assert term(env, 0, "center") == pytest.approx(2e-3 * (-dev + 0.05 / math.exp(dev - 0.5)), rel=1e-5)
    assert term(env, 0, "align") == pytest.approx(1e-2 * (0.0025 * (1 - 0.1 / (math.pi / 2))), rel=1e-4)
    assert term(env, 0, "velocity") == pytest.approx(2.5e-4 * math.cos(0.1), rel=1e-5)
    assert env.rewards[0] == pytest.approx(env.reward_terms[0].sum(), rel=1e-6)


def test_wrong_way_and_slow_driving(straight_map):
    # heading west on the east lane: the west lane (compatible direction) wins and the car is
    # 3.5 m to its left (s = -3.5)
    env = env_for(straight_map, [dict(xy=(0.0, -2.0), heading=math.pi, speed=1.0)])
    assert env.buffers["lane_s"][0] == pytest.approx(-3.5, abs=1e-5)
    assert term(env, 0, "velocity") == 0.0  # below 2.5 m/s
    # beyond lane_radius of any compatible lane: the nearest lane of any direction, alpha = pi
    env = env_for(
        straight_map, [dict(xy=(0.0, -2.0), heading=math.pi, speed=5.0)], params=SimParams(lane_radius=3.0)
    )
    assert abs(env.buffers["lane_alpha"][0]) == pytest.approx(math.pi, abs=1e-5)
    assert term(env, 0, "align") == pytest.approx(1e-2 * (-1.0 + 0.0025 * (1 - 2.0)), rel=1e-4)
    assert term(env, 0, "center") == 0.0 and term(env, 0, "velocity") == 0.0


def test_pedestrian_collision_counts_as_collision(straight_map):
    ped = dict(path=[(6.0, -2.0), (6.0, 3.0)], speed=1.0, start=100.0)  # waits in the lane
    env = env_for(straight_map, [dict(xy=(0.0, -2.0), speed=10.0)], steps=5, peds=[ped])
    assert env.buffers["ever"][0] & 2
    assert env.pop_episode_stats() == []


def test_terminated_vehicle_obstacle_mode(straight_map):
    a = dict(xy=(0.0, -2.0), speed=0.0, coeffs=dict(collision=0.9))
    b = dict(xy=(3.0, -2.0), speed=0.0, coeffs=dict(collision=0.9))
    c = dict(xy=(-8.0, -2.0), speed=8.0, coeffs=dict(collision=0.1))
    env = env_for(straight_map, [a, b, c], steps=1, terminated_vehicle="obstacle")
    assert env.terminations[0] and env.terminations[1]
    assert env.buffers["obstacle"][0] and env.masks[2]
    for _ in range(9):
        env.step(np.tile(np.asarray(ZERO, np.int64), (env.num_agents, 1)))
    assert env.buffers["ever"][2] & 1  # drove into the obstacles
    env = env_for(straight_map, [a, b, c], steps=10, terminated_vehicle="remove")
    assert not env.buffers["ever"][2] & 1
