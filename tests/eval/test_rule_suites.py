"""Failure-mode suites (paper sections 5.1-5.2): red lights (stopped / ran / bypassed, classified
from geometry, not from the simulator's red-light event), stop signs (full / rolling / no stop,
with and without cross traffic) and the crosswalk suite's road-edge outcome; each checked on
scripted drivers with known behaviour, on the bundled town and on Tartu."""

from __future__ import annotations

import json

import numpy as np
import pytest
import shapely
from sharedmaps import shared_map

from selfplaydrive.drivers import RuleBasedDriver
from selfplaydrive.eval.suites import (
    CrosswalkSuite,
    RedLightSuite,
    StopSignSuite,
    classify_crosswalk,
    classify_red_light,
    run_all_suites,
    run_suite,
    scripted,
)
from selfplaydrive.eval.suites.base import Trajectory
from selfplaydrive.eval.suites.red_lights import SWERVE
from selfplaydrive.eval.suites.shapes import box_polygons, offset_path
from selfplaydrive.eval.suites.stop_signs import STOP_ZONE
from selfplaydrive.maps.lane_paths import point_at, project
from selfplaydrive.maps.loader import load_map
from selfplaydrive.maps.roadmap import StopKind
from selfplaydrive.scenario.lights import RED
from selfplaydrive.sim.actions import ContinuousActions
from selfplaydrive.sim.vec_env import VecEnv


@pytest.fixture(scope="module")
def town():
    return load_map("default")


@pytest.fixture(scope="module")
def tartu():
    return load_map(str(shared_map("tartu_lanelet2/tartu_demo_l.osm")))


@pytest.fixture(scope="module")
def town_red(town):
    return RedLightSuite().generate(town, np.random.default_rng(4), 6)


@pytest.fixture(scope="module")
def tartu_red(tartu):
    return RedLightSuite().generate(tartu, np.random.default_rng(4), 8)


def _outcomes(suite, road_map, items, plan_fn):
    env = lambda spawner, n: VecEnv(road_map, spawner, n, actions=ContinuousActions())  # noqa: E731
    trajs = run_suite(env, scripted.ScriptedDriver.factory(plan_fn), items)
    return [suite.classify(i, t) for i, t in zip(items, trajs, strict=True)]


def _still(item, frames: int = 50, slot_xy=None) -> Trajectory:
    """A hand-made trajectory: the ego standing at its start (or at `slot_xy` per frame)."""
    sc = item.scenario
    xy = np.repeat(sc.agent_xy[None], frames, axis=0).astype(np.float32)
    hd = np.repeat(sc.agent_heading[None], frames, axis=0).astype(np.float32)
    if slot_xy is not None:
        xy[:, 0], hd[:, 0] = slot_xy
    A = len(sc.agent_xy)
    return Trajectory(
        dt=0.1,
        xy=xy,
        heading=hd,
        speed=np.zeros((frames, A), np.float32),
        active=np.ones((frames, A), bool),
        ped_xy=np.zeros((frames, 1, 2), np.float32),
        collided=np.zeros(A, bool),
        collision_frame=np.full(A, -1, np.int32),
        offroad=np.zeros(A, bool),
    )


# -- red lights: generation ------------------------------------------------------------------
def _check_red(road_map, items) -> None:
    for it in items:
        sc, info = it.scenario, it.info
        assert sc.lights_enabled and sc.agent_valid.tolist() == [True, False]
        groups = road_map.light_group[info["red_lines"]]
        assert info["light_line"] in info["red_lines"]
        assert np.all(sc.light_state[groups] == RED)
        assert np.all(sc.light_time_left > sc.episode_length)  # red for the whole episode
        # the ego starts on its path, wholly behind the gate, `start_gap_m` before the line
        s, _, d = project(it.paths["ego"], sc.agent_xy[:1].astype(np.float64))
        assert d[0] < 0.05
        front = s[0] + info["ego_length_m"] / 2
        assert front + info["start_gap_m"] == pytest.approx(info["line_arc_m"], abs=0.05)
        assert 45.0 <= info["start_gap_m"] <= 80.0
        size = (info["ego_length_m"], info["ego_width_m"])
        box = box_polygons(sc.agent_xy[:1], sc.agent_heading[:1], *size)[0]
        assert not box.intersects(shapely.Polygon(it.paths["area"]))
        # the line point of the path is on the gate, the gate is labelled behind the red line
        c, _ = point_at(it.paths["ego"], info["line_arc_m"])
        assert shapely.LineString(it.paths["gate"]).distance(shapely.Point(c)) < 1e-6
        assert any(lab == "controlled" and t0 <= 0.0 <= t1 for t0, t1, lab in info["gate_labels"])


def test_red_light_generator_on_bundled_town(town, town_red):
    assert len(town_red) == 6
    _check_red(town, town_red)
    assert sum(it.info["oncoming_offset_m"] is not None for it in town_red) >= 3


def test_red_light_generator_on_tartu(tartu, tartu_red):
    assert len(tartu_red) == 8
    _check_red(tartu, tartu_red)


# -- red lights: scripted drivers ------------------------------------------------------------
def _check_scripted_red(road_map, items) -> None:
    suite = RedLightSuite()
    comply = _outcomes(suite, road_map, items, scripted.red_light_plans("comply"))
    assert [o["outcome"] for o in comply] == ["stopped"] * len(items)
    assert all(not o["line_touched"] and not o["sim_red_light"] for o in comply)
    run = _outcomes(suite, road_map, items, scripted.red_light_plans("run"))
    assert [o["outcome"] for o in run] == ["ran"] * len(items)
    assert all(o["entry_via"] == "controlled" and o["sim_red_light"] for o in run)
    around = [it for it in items if it.info["oncoming_offset_m"] is not None]
    bypass = _outcomes(suite, road_map, around, scripted.red_light_plans("bypass"))
    assert [o["outcome"] for o in bypass] == ["bypassed"] * len(around)
    assert all(o["entry_via"] == "oncoming" and not o["line_touched"] for o in bypass)
    # the paper's reward hack: the simulator's red-light event misses bypasses
    assert sum(not o["sim_red_light"] for o in bypass) >= len(around) // 2
    summary = suite.summarise(comply + run + bypass)
    assert summary["n"] == 2 * len(items) + len(around)
    assert summary["bypassed"]["numerator"] == len(around) and summary["entry_via"]["oncoming"] == len(around)


def test_red_light_classifier_on_scripted_drivers_town(town, town_red):
    _check_scripted_red(town, town_red)


def test_red_light_classifier_on_scripted_drivers_tartu(tartu, tartu_red):
    assert sum(it.info["oncoming_offset_m"] is not None for it in tartu_red) >= 3
    _check_scripted_red(tartu, tartu_red)


def test_red_light_classifier_on_hand_made_trajectories(town_red):
    """Pure function: standing still, driving along the lane, driving along the oncoming lane."""
    it = next(i for i in town_red if i.info["oncoming_offset_m"] is not None)
    info, path = it.info, it.paths["ego"]
    still = classify_red_light(it, _still(it))
    assert still["outcome"] == "stopped" and still["entry_s"] is None and still["sim_red_light"] is None
    line = info["line_arc_m"]
    s = np.linspace(info["start_arc_m"], line + 20.0, 80)
    assert classify_red_light(it, _still(it, 80, point_at(path, s)))["outcome"] == "ran"
    shifted = offset_path(path, info["oncoming_offset_m"], (line - SWERVE[0], line - SWERVE[1]))
    res = classify_red_light(it, _still(it, 80, point_at(shifted, s)))
    assert res["outcome"] == "bypassed" and res["entry_via"] == "oncoming"
    # stopping with the bumper 0.3 m over the line touches it but does not enter
    stop = np.full(40, line - info["ego_length_m"] / 2 + 0.3)
    over = classify_red_light(it, _still(it, 40, point_at(path, stop)))
    assert over["outcome"] == "stopped" and over["line_touched"]
    # leaving the road before the junction is no stop
    off = _still(it)
    off.offroad[0] = True
    assert classify_red_light(it, off)["outcome"] == "offroad"


# -- stop signs ------------------------------------------------------------------------------
def _check_stop_pairs(road_map, items) -> None:
    n = len(items) // 2
    for w, wo in zip(items[:n], items[n:], strict=True):
        assert (w.info["traffic"], wo.info["traffic"]) == ("with", "without")
        assert w.scenario.agent_valid.tolist() == [True, True]
        assert wo.scenario.agent_valid.tolist() == [False, True]
        np.testing.assert_array_equal(w.scenario.agent_xy[1], wo.scenario.agent_xy[1])
        kind = StopKind(int(road_map.stop_kind[w.info["stop_line"]]))
        assert w.info["kind"] == ("stop" if kind == StopKind.STOP else "yield")
        front = w.info["side_start_arc_m"] + w.scenario.agent_length[1] / 2
        assert w.info["stop_arc_m"] - front >= 15.0  # room for a full stop


def _check_scripted_stop(road_map, items) -> None:
    suite = StopSignSuite()
    full = _outcomes(suite, road_map, items, scripted.stop_sign_plans("full"))
    assert [o["outcome"] for o in full] == ["full_stop"] * len(items)
    assert not any(o["collided"] for o in full)
    rolling = _outcomes(suite, road_map, items, scripted.stop_sign_plans("rolling"))
    assert [o["outcome"] for o in rolling] == ["rolling_stop"] * len(items)
    assert all(0.5 <= o["min_zone_speed_mps"] < 3.0 for o in rolling)
    none = _outcomes(suite, road_map, items, scripted.stop_sign_plans("none"))
    assert [o["outcome"] for o in none] == ["no_stop"] * len(items)
    # the paper's observation, scripted: a full stop only when cross traffic comes
    only = _outcomes(
        suite,
        road_map,
        items,
        lambda it: scripted.stop_sign_plans("full" if it.scenario.agent_valid[0] else "none")(it),
    )
    n = len(items) // 2
    for kind in {it.info["kind"] for it in items}:
        paired = suite.summarise(only)[kind]["paired"]
        k = sum(it.info["kind"] == kind for it in items[:n])
        assert paired == {"both": 0, "only_with_traffic": k, "only_without_traffic": 0, "neither": 0}


def test_stop_signs_on_bundled_town(town):
    items = StopSignSuite().generate(town, np.random.default_rng(5), 3)
    assert len(items) == 6
    _check_stop_pairs(town, items)
    _check_scripted_stop(town, items)
    # the procedural town has STOP lines where a minor street crosses a main road (regulation.py)
    stops = StopSignSuite(kinds=("stop",)).generate(town, np.random.default_rng(5), 3)
    assert {it.info["kind"] for it in stops} == {"stop"} and len(stops) == 6


def test_stop_signs_on_tartu(tartu):
    items = StopSignSuite().generate(tartu, np.random.default_rng(5), 4)
    assert len(items) == 8
    _check_stop_pairs(tartu, items)
    _check_scripted_stop(tartu, items)
    stops = StopSignSuite(kinds=("stop",)).generate(tartu, np.random.default_rng(5), 3)
    assert {it.info["kind"] for it in stops} == {"stop"} and len(stops) == 6


def test_stop_sign_bad_kinds_raise():
    with pytest.raises(ValueError, match="kinds"):
        StopSignSuite(kinds=("give_way",))


def test_stop_sign_zone_bounds_the_stop(town):
    """A stop further back than the zone is no stop at the line: "not_reached" when the car
    never gets to the line afterwards."""
    item = StopSignSuite().generate(town, np.random.default_rng(6), 1)[1]  # without traffic
    info = item.info
    half = float(item.scenario.agent_length[1]) / 2
    far = np.full(30, info["stop_arc_m"] - half - STOP_ZONE - 3.0)
    xy, hd = point_at(item.paths["side"], far)
    traj = _still(item, 30)
    traj.xy[:, 1], traj.heading[:, 1] = xy, hd
    assert StopSignSuite().classify(item, traj)["outcome"] == "not_reached"
    near = np.full(30, info["stop_arc_m"] - half - 2.0)
    traj.xy[:, 1], traj.heading[:, 1] = point_at(item.paths["side"], near)
    assert StopSignSuite().classify(item, traj)["outcome"] == "full_stop"


# -- crosswalks: road edge -------------------------------------------------------------------
def test_crosswalk_road_edge_is_not_other(town):
    item = CrosswalkSuite().generate(town, np.random.default_rng(3), 1)[0]
    traj = _still(item, 20)
    traj.speed[:] = 2.0  # never stops, never passes
    assert classify_crosswalk(item, traj)["outcome"] == "other"
    traj.offroad[0] = True
    assert classify_crosswalk(item, traj)["outcome"] == "road_edge"
    summary = CrosswalkSuite().summarise([classify_crosswalk(item, traj)])
    assert summary["waiting"]["road_edge"]["numerator"] == 1


# -- end to end ------------------------------------------------------------------------------
def test_run_all_failure_suites_with_rule_based_driver(town, tartu):
    counts = {"red_lights": 4, "stop_signs": 2, "spawn_sanity": 4}
    res = run_all_suites([town, tartu], RuleBasedDriver, counts, seed=0)
    json.dumps(res, allow_nan=False)
    red = res["red_lights"]
    assert red["generated"] == 4 and {r["info"]["map"] for r in red["scenarios"]} == {town.name, tartu.name}
    outcomes = ("stopped", "ran", "bypassed", "collision", "offroad")
    assert sum(red["summary"][k]["numerator"] for k in outcomes) == 4
    # the rule-based driver keeps to its lane: it never goes around a red line
    assert red["summary"]["bypassed"]["numerator"] == 0
    assert res["stop_signs"]["generated"] == 4
    spawn = res["spawn_sanity"]["summary"]
    assert spawn["n"] == 4 and spawn["overlap"]["numerator"] == 0
