"""Rule-adherence suites (paper section 5.3): generators on the bundled town and on Tartu,
classifiers on scripted drivers with known behaviour, the stop-line mask, and an end-to-end
run of every suite with the rule-based driver."""

from __future__ import annotations

import json

import numpy as np
import pytest
from lanegraph import reaches_by_following
from sharedmaps import shared_map

from selfplaydrive.drivers import RuleBasedDriver
from selfplaydrive.eval.suites import (
    CrosswalkSuite,
    FixedScenarioSpawner,
    StopLineSuite,
    TurnLaneSuite,
    hide_stop_lines,
    run_all_suites,
    run_suite,
    scripted,
)
from selfplaydrive.eval.suites.base import Trajectory
from selfplaydrive.eval.suites.stop_lines import classify_stop_line, constant_speed_collision
from selfplaydrive.maps.lane_paths import point_at, project
from selfplaydrive.maps.loader import load_map
from selfplaydrive.maps.roadmap import SegmentType
from selfplaydrive.obs.layout import ObsLayout
from selfplaydrive.sim.actions import ContinuousActions
from selfplaydrive.sim.vec_env import VecEnv


@pytest.fixture(scope="module")
def town():
    return load_map("default")


@pytest.fixture(scope="module")
def tartu():
    return load_map(str(shared_map("tartu_lanelet2/tartu_demo_l.osm")))


@pytest.fixture(scope="module")
def items(town):
    """A few scenarios of each suite on the bundled town (fixed seeds)."""
    return {
        "turn": TurnLaneSuite().generate(town, np.random.default_rng(1), 4),
        "stop": StopLineSuite().generate(town, np.random.default_rng(2), 4),
        "cross": CrosswalkSuite().generate(town, np.random.default_rng(3), 3),
    }


def _continuous(road_map):
    return lambda spawner, n: VecEnv(road_map, spawner, n, actions=ContinuousActions())


def _on_lane(road_map, item, slot: int) -> None:
    """The agent's centre lies on its start lane's centerline, heading along it."""
    sc = item.scenario
    line = road_map.lanes.centerlines[int(sc.agent_lane[slot])].astype(np.float64)
    s, _, dist = project(line, sc.agent_xy[slot : slot + 1].astype(np.float64))
    _, hd = point_at(line, s)
    assert dist[0] < 0.05
    assert abs(np.angle(np.exp(1j * (hd[0] - sc.agent_heading[slot])))) < 0.05


# -- generators ------------------------------------------------------------------------------
def _check_turn(road_map, items) -> None:
    for it in items:
        sc, info = it.scenario, it.info
        assert sc.agent_valid.tolist() == [True, False] and not sc.ped_valid.any() and not sc.lights_enabled
        _on_lane(road_map, it, 0)
        # the start lane cannot reach the turn by following lanes: a lane change is needed
        assert not reaches_by_following(road_map, info["start_lane"], info["junction_lane"])
        assert reaches_by_following(road_map, info["approach_lane"], info["junction_lane"])
        assert 30.0 <= info["start_distance_m"] <= 100.0
        _, lat, _ = project(it.paths["corridor"], sc.agent_xy[:1].astype(np.float64))
        assert abs(lat[0]) >= 0.75 * info["lane_width_m"]
        _, _, d = project(it.paths["exit"], sc.waypoints[0, :2].astype(np.float64))
        assert d.max() < 0.05 and sc.num_waypoints[0] == 2
        assert sc.coeffs[0, 1] == 1.0  # evaluation coefficients: C_collision at its maximum


def _check_stop(road_map, items) -> None:
    for it in items:
        sc, info = it.scenario, it.info
        assert sc.agent_valid.all()
        _on_lane(road_map, it, 0)
        _on_lane(road_map, it, 1)
        hit, t = constant_speed_collision(it)
        assert hit and t <= info["time_to_conflict_s"] + 0.05
        # both centres reach the conflict point at the same time T
        for key in ("main", "side"):
            arrive = (info[f"{key}_conflict_arc_m"] - info[f"{key}_start_arc_m"]) / info[f"{key}_speed_mps"]
            assert arrive == pytest.approx(info["time_to_conflict_s"], rel=1e-9)
        # the side vehicle starts wholly behind its stop line
        assert info["side_start_arc_m"] + sc.agent_length[1] / 2 < info["stop_arc_m"]
        side_lanes = road_map.stop_lane_index[
            road_map.stop_lane_offsets[info["stop_line"]] : road_map.stop_lane_offsets[info["stop_line"] + 1]
        ]
        assert info["side_lane"] in side_lanes


def _check_cross(road_map, items) -> None:
    n = len(items) // 2
    for it, twin in zip(items[:n], items[n:], strict=True):
        assert (it.info["variant"], twin.info["variant"]) == ("waiting", "crossing")
        np.testing.assert_array_equal(it.scenario.agent_xy, twin.scenario.agent_xy)
        assert it.scenario.ped_start_time[0] > it.scenario.episode_length
        _on_lane(road_map, it, 0)
        info = twin.info
        ego_t = (info["crossing_arc_m"] - info["ego_start_arc_m"]) / info["ego_speed_mps"]
        ped_t = twin.scenario.ped_start_time[0] + info["ped_to_crossing_m"] / info["ped_speed_mps"]
        assert ego_t == pytest.approx(ped_t, rel=1e-5)
        gap = info["crosswalk_in_arc_m"] - info["ego_start_arc_m"] - info["ego_length_m"] / 2
        assert gap >= 15.0
        # the walking line crosses the ego path at the crossing arc
        x, _ = point_at(it.paths["ego"], info["crossing_arc_m"])
        _, _, d = project(it.paths["ped"], x[None])
        assert d[0] < 0.05


def test_generators_on_bundled_town(town, items):
    assert [len(items["turn"]), len(items["stop"]), len(items["cross"])] == [4, 4, 6]
    _check_turn(town, items["turn"])
    _check_stop(town, items["stop"])
    _check_cross(town, items["cross"])


def test_generators_on_tartu(tartu):
    turn = TurnLaneSuite().generate(tartu, np.random.default_rng(0), 6)
    stop = StopLineSuite().generate(tartu, np.random.default_rng(0), 4)
    cross = CrosswalkSuite().generate(tartu, np.random.default_rng(0), 6)
    assert [len(turn), len(stop), len(cross)] == [6, 4, 12]
    _check_turn(tartu, turn)
    _check_stop(tartu, stop)
    _check_cross(tartu, cross)


def test_map_without_enough_places_gives_fewer_with_a_warning(tartu):
    with pytest.warns(UserWarning, match=r"stop_lines: map 'tartu_demo_l' yields \d+ of count=500"):
        got = StopLineSuite().generate(tartu, np.random.default_rng(0), 500)
    assert 0 < len(got) < 500


def test_bad_settings_raise():
    with pytest.raises(ValueError, match=r"start_distance.*\(50.0, 10.0\)"):
        TurnLaneSuite(start_distance=(50.0, 10.0))
    with pytest.raises(ValueError, match="variants"):
        CrosswalkSuite(variants=("running",))
    with pytest.raises(ValueError, match="at least one scenario"):
        FixedScenarioSpawner([])


# -- runner and mask -------------------------------------------------------------------------
def test_worlds_get_scenarios_in_order_over_batches(town, items):
    stop = items["stop"]
    trajs = run_suite(
        _continuous(town), scripted.ScriptedDriver.factory(scripted.stop_line_plans(None)), stop, batch_size=3
    )
    assert len(trajs) == 4
    for it, tr in zip(stop, trajs, strict=True):
        np.testing.assert_allclose(tr.xy[0], it.scenario.agent_xy, atol=1e-4)
        assert len(tr.xy) > 10


def test_hide_stop_lines_blanks_only_stop_line_rows():
    layout = ObsLayout(max_objects=2, max_road=4)
    obs = np.zeros((1, layout.obs_dim), np.float32)
    road = layout.split(obs)["road"]
    types = [SegmentType.LANE_CENTER, SegmentType.STOP_LINE, SegmentType.CROSSWALK, SegmentType.STOP_LINE]
    for k, t in enumerate(types):
        road[0, k, :] = 0.3
        road[0, k, layout.feature_index("road", "valid")] = 1.0
        road[0, k, layout.feature_index("road", "type")] = t / 4.0
    out = hide_stop_lines(obs, layout)
    out_road = layout.split(out)["road"]
    assert np.all(out_road[0, [1, 3]] == 0.0)
    np.testing.assert_array_equal(out_road[0, [0, 2]], road[0, [0, 2]])
    assert obs[0, layout.road_offset] == 1.0  # the input is untouched


# -- classifiers on scripted drivers -----------------------------------------------------------
def _outcomes(suite, road_map, items, plan_fn):
    trajs = run_suite(_continuous(road_map), scripted.ScriptedDriver.factory(plan_fn), items)
    return [suite.classify(i, t) for i, t in zip(items, trajs, strict=True)]


def test_turn_classifier_on_scripted_drivers(town, items):
    suite = TurnLaneSuite()
    early = _outcomes(suite, town, items["turn"], scripted.turn_early_change)
    assert [o["outcome"] for o in early] == ["correct_lane"] * 4
    for o, it in zip(early, items["turn"], strict=True):
        # the change is done within ~15 m of the start, so long before the junction
        assert o["lane_change_lead_m"] > it.info["start_distance_m"] - 20.0
        assert o["lane_change_lead_s"] > 1.0 and o["entry_offset_m"] < 0.5
    wrong = _outcomes(suite, town, items["turn"], scripted.turn_from_wrong_lane)
    assert [o["outcome"] for o in wrong] == ["wrong_lane"] * 4
    assert all(o["entry_offset_m"] > 2.5 for o in wrong)


def test_stop_line_classifier_on_scripted_drivers(town, items):
    suite, stop = StopLineSuite(), items["stop"]
    assert [o["outcome"] for o in _outcomes(suite, town, stop, scripted.stop_line_plans(None))] == [
        "collision"
    ] * 4
    side = _outcomes(suite, town, stop, scripted.stop_line_plans("side"))
    assert [o["outcome"] for o in side] == ["side_yielded"] * 4
    assert all(o["side_min_speed_mps"] < 0.5 for o in side)
    main = _outcomes(suite, town, stop, scripted.stop_line_plans("main"))
    assert [o["outcome"] for o in main] == ["main_yielded"] * 4


def test_crosswalk_classifier_on_scripted_drivers(town, items):
    suite, cross = CrosswalkSuite(), items["cross"]
    const = [o["outcome"] for o in _outcomes(suite, town, cross, scripted.crosswalk_plans("constant"))]
    assert const == ["passed"] * 3 + ["collision"] * 3
    slow = [o["outcome"] for o in _outcomes(suite, town, cross, scripted.crosswalk_plans("slow"))]
    assert slow == ["passed"] * 3 + ["passed_behind"] * 3
    stop = [o["outcome"] for o in _outcomes(suite, town, cross, scripted.crosswalk_plans("stop"))]
    assert stop == ["stopped"] * 6
    # the pedestrian starts 4 s late: a constant-speed ego passes in front of it
    late = [it for it in cross if it.info["variant"] == "crossing"]
    for it in late:
        it.scenario.ped_start_time[0] += 4.0
    try:
        front = _outcomes(suite, town, late, scripted.crosswalk_plans("constant"))
    finally:
        for it in late:
            it.scenario.ped_start_time[0] -= 4.0
    assert [o["outcome"] for o in front] == ["passed_in_front"] * 3
    assert all(o["ped_progress_m"] < 0 for o in front)


def test_stop_line_classifier_on_hand_made_trajectory(items):
    """Pure function: main at constant speed, side standing still -> side yielded, with the
    main vehicle's pass time = time to conflict."""
    it = items["stop"][0]
    info, dt, frames = it.info, 0.1, 120
    t = np.arange(frames) * dt
    xy = np.zeros((frames, 2, 2), np.float32)
    hd = np.zeros((frames, 2), np.float32)
    main_xy, main_hd = point_at(it.paths["main"], info["main_start_arc_m"] + info["main_speed_mps"] * t)
    side_xy, side_hd = point_at(it.paths["side"], np.full(frames, info["side_start_arc_m"]))
    xy[:, 0], xy[:, 1], hd[:, 0], hd[:, 1] = main_xy, side_xy, main_hd, side_hd
    speed = np.stack([np.full(frames, info["main_speed_mps"]), np.zeros(frames)], axis=1)
    traj = Trajectory(
        dt=dt,
        xy=xy,
        heading=hd,
        speed=speed.astype(np.float32),
        active=np.ones((frames, 2), bool),
        ped_xy=np.zeros((frames, 1, 2), np.float32),
        collided=np.zeros(2, bool),
        collision_frame=np.full(2, -1, np.int32),
        offroad=np.zeros(2, bool),
    )
    res = classify_stop_line(it, traj)
    assert res["outcome"] == "side_yielded" and res["side_pass_s"] is None
    assert res["main_pass_s"] == pytest.approx(info["time_to_conflict_s"], abs=dt + 1e-6)
    traj.collided[1] = True
    assert classify_stop_line(it, traj)["outcome"] == "collision"


# -- end to end ------------------------------------------------------------------------------
def test_run_all_suites_with_rule_based_driver(town):
    res = run_all_suites(town, RuleBasedDriver, {"turn_lanes": 3, "stop_lines": 3, "crosswalks": 2}, seed=0)
    json.dumps(res, allow_nan=False)
    assert res["turn_lanes"]["generated"] == 3 and res["stop_lines"]["generated"] == 3
    assert res["crosswalks"]["generated"] == 4
    turn = res["turn_lanes"]["summary"]["all"]
    # the rule-based driver never changes lanes, so it never turns from the correct lane
    assert turn["correct_lane"]["numerator"] == 0 and turn["n"] == 3
    stop = res["stop_lines"]
    assert (
        sum(
            stop["summary"][k]["numerator"]
            for k in ("collision", "side_yielded", "main_yielded", "unresolved")
        )
        == 3
    )
    # the rule-based driver ignores stop lines, so hiding them changes nothing
    assert stop["changed"]["changed"] == 0
    waiting = res["crosswalks"]["summary"]["waiting"]
    assert waiting["n"] == 2 and 0.0 <= waiting["passed"]["lo"] <= waiting["passed"]["hi"] <= 1.0


def test_turn_lane_entry_waypoint_variant_names_the_correct_lane():
    """With `entry_waypoint`, the first waypoint lies on the correct corridor that far before the
    junction and the exit waypoints follow; without it the exit waypoints come first."""
    from selfplaydrive.eval.suites.turn_lanes import TurnLaneSuite
    from selfplaydrive.maps.lane_paths import cumlen, project
    from selfplaydrive.maps.loader import load_map

    town = load_map("default")
    plain = TurnLaneSuite().generate(town, np.random.default_rng(2), 4)
    named = TurnLaneSuite(entry_waypoint=15.0).generate(town, np.random.default_rng(2), 4)
    assert len(plain) == len(named) == 4
    for item in plain:
        assert item.scenario.num_waypoints[0] == 2
    for item in named:
        sc, corridor = item.scenario, item.paths["corridor"]
        assert sc.num_waypoints[0] == 3
        s, lat, _ = project(corridor, sc.waypoints[0, :1].astype(np.float64))
        assert abs(lat[0]) < 0.01
        assert s[0] == pytest.approx(item.info["entry_arc_m"] - 15.0, abs=0.01)
        assert item.info["start_distance_m"] > 15.0
        assert cumlen(corridor)[-1] > s[0]
    with pytest.raises(ValueError, match="entry_waypoint"):
        TurnLaneSuite(entry_waypoint=-1.0)
