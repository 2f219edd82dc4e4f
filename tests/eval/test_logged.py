"""Logged scenarios in the GPUDrive JSON layout: loader, scenario builder, Waymax-style closed loop.

Every file here is synthetic, written into tmp_path (no Waymo-derived data is ever committed).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from selfplaydrive.errors import MapError
from selfplaydrive.eval.logged import build_scenario, evaluate_logged, load_gpudrive_json, run_logged
from selfplaydrive.eval.logged.run import path_waypoints
from selfplaydrive.eval.longform import RuleBasedPolicy

T = 91
OFFSET = np.array([1000.0, -500.0])  # file coordinates far from 0, so the recentring shows


def _obj(xy, heading, speed, valid=None, kind="vehicle", length=4.5, width=2.0, oid=0):
    xy = np.asarray(xy, float) + OFFSET
    heading = np.broadcast_to(np.asarray(heading, float), (T,))
    speed = np.broadcast_to(np.asarray(speed, float), (T,))
    valid = np.ones(T, bool) if valid is None else np.asarray(valid, bool)
    return {
        "position": [{"x": float(x), "y": float(y), "z": 0.0} for x, y in xy],
        "heading": [float(h) for h in heading],
        "velocity": [
            {"x": float(v * math.cos(h)), "y": float(v * math.sin(h))}
            for v, h in zip(speed, heading, strict=True)
        ],
        "valid": [bool(v) for v in valid],
        "width": width,
        "length": length,
        "height": 1.5,
        "type": kind,
        "id": oid,
        "goalPosition": {"x": float(xy[-1, 0]), "y": float(xy[-1, 1])},
        "mark_as_expert": 0,
    }


def _road(kind, pts, rid):
    pts = np.asarray(pts, float) + OFFSET
    return {"type": kind, "id": rid, "geometry": [{"x": float(x), "y": float(y), "z": 0.0} for x, y in pts]}


def _straight(tmp_path, name="straight.json", degrees=False, extra=()):
    """A 300 m straight one-lane road along +x, edges at y = -2 (drivable left of +x) and y = +2
    (drawn along -x); ego at 10 m/s reaching x = 0 at t = 10, a lead 30 m ahead at 8 m/s, a parked
    car off the lane, a pedestrian walking along the far side."""
    t = np.arange(T) * 0.1
    ego = np.c_[-10.0 + 10.0 * t, np.zeros(T)]
    lead = np.c_[20.0 + 8.0 * (t - 1.0), np.zeros(T)]
    parked = np.c_[np.full(T, 60.0), np.full(T, 5.0)]
    ped = np.c_[np.full(T, 40.0) + 1.2 * t, np.full(T, 3.5)]
    h = np.degrees(0.0) if degrees else 0.0
    objects = [
        _obj(ego, h, 10.0, oid=11),
        _obj(lead, h, 8.0, oid=12),
        _obj(parked, h, 0.0, oid=13),
        _obj(ped, h, 1.2, kind="pedestrian", length=0.6, width=0.6, oid=14),
    ]
    xs = np.arange(-100.0, 201.0, 10.0)
    roads = [
        _road("lane", np.c_[xs, np.zeros_like(xs)], 1),
        _road("road_edge", np.c_[xs, np.full_like(xs, -2.0)], 2),
        _road("road_edge", np.c_[xs[::-1], np.full_like(xs, 2.0)], 3),
        _road("road_line", np.c_[xs, np.full_like(xs, 1.0)], 4),
        _road("lane", [[5.0, 5.0]], 5),  # one point: skipped
        _road("crosswalk", [[100, -2], [104, -2], [104, 2], [100, 2], [100, -2]], 6),
        *extra,
    ]
    data = {"name": "", "scenario_id": "synthetic-straight", "objects": objects, "roads": roads,
            "tl_states": {}, "metadata": {"sdc_track_index": 0}}  # fmt: skip
    p = tmp_path / name
    p.write_text(json.dumps(data))
    return p


def _bend(tmp_path):
    """A lane going 40 m east, then a quarter circle (R = 20 m) to the north; edges +-2 m. The
    logged ego follows the lane at 8 m/s."""
    a = np.linspace(0.0, np.pi / 2, 16)[1:]
    centre = np.r_[
        np.c_[np.arange(0.0, 41.0, 5.0), np.zeros(9)], np.c_[40 + 20 * np.sin(a), 20 - 20 * np.cos(a)]
    ]
    centre = np.r_[centre, np.c_[np.full(6, 60.0), 20.0 + np.arange(1, 7) * 10.0]]
    d = np.gradient(centre, axis=0)
    n = np.c_[-d[:, 1], d[:, 0]] / np.linalg.norm(d, axis=1)[:, None]  # left normal
    seg = np.linalg.norm(np.diff(centre, axis=0), axis=1)
    cum = np.r_[0.0, np.cumsum(seg)]
    s = 8.0 * np.arange(T) * 0.1
    xy = np.c_[np.interp(s, cum, centre[:, 0]), np.interp(s, cum, centre[:, 1])]
    head = np.arctan2(np.interp(s, cum, d[:, 1]), np.interp(s, cum, d[:, 0]))
    roads = [
        _road("lane", centre, 1),
        _road("road_edge", centre - 2 * n, 2),
        _road("road_edge", (centre + 2 * n)[::-1], 3),
    ]
    data = {"objects": [_obj(xy, head, 8.0)], "roads": roads, "tl_states": {}}
    p = tmp_path / "bend.json"
    p.write_text(json.dumps(data))
    return p


def _constant(accel: float):
    def policy(obs, env):
        t = env.action_table
        row = [int(np.argmin(np.abs(t.accel - accel))), int(np.argmin(np.abs(t.steer)))]
        return np.tile(row, (env.num_agents, 1))

    return policy


def test_loader_reads_tracks_and_map(tmp_path):
    log = load_gpudrive_json(_straight(tmp_path))
    assert log.name == "synthetic-straight" and log.num_steps == T and log.sdc == 0
    assert list(log.kind) == ["vehicle", "vehicle", "vehicle", "pedestrian"]
    assert list(log.object_id) == [11, 12, 13, 14]
    # tracks are shifted exactly like the recentred map
    np.testing.assert_allclose(log.shift, log.road_map.origin)
    np.testing.assert_allclose(log.xy[0, 10] + log.shift, OFFSET, atol=1e-9)
    lane = log.road_map.lanes.centerlines[0].astype(float) + log.shift
    np.testing.assert_allclose(lane[[0, -1]], np.add(OFFSET, [[-100, 0], [200, 0]]), atol=1e-3)
    np.testing.assert_allclose(log.vel[1, 5], [8.0, 0.0])
    assert len(log.road_map.lanes) == 1 and len(log.road_map.road_edges) == 2
    assert len(log.road_map.crosswalks) == 1
    assert log.skipped == {"short_lane": 1, "short_edge": 0, "short_crosswalk": 0, "unused_type": 1}
    assert log.ego_index() == 0 and len(log.edges) == 2


def test_loader_heading_in_degrees_and_lane_successors(tmp_path):
    t = np.arange(T) * 0.1
    north = _obj(np.c_[np.zeros(T), 10.0 * t], 90.0, 10.0)  # heading in degrees (Nocturne files)
    north["velocity"] = [{"x": 0.0, "y": 10.0}] * T
    roads = [_road("lane", [[0, -10], [0, 50]], 1), _road("lane", [[0.5, 50.3], [0, 120]], 2)]
    p = tmp_path / "deg.json"
    p.write_text(json.dumps({"objects": [north], "roads": roads}))
    log = load_gpudrive_json(p)
    assert log.heading[0, 0] == pytest.approx(np.pi / 2)
    assert list(log.road_map.lanes.successors(0)) == [1]  # 0.58 m gap <= connect_tol
    assert list(load_gpudrive_json(p, connect_tol=0.3).road_map.lanes.successors(0)) == []
    with pytest.raises(ValueError, match="heading_unit"):
        load_gpudrive_json(p, heading_unit="grad")


@pytest.mark.parametrize(
    ("mutate", "match"),
    [
        (lambda d: d.pop("objects"), "objects"),
        (lambda d: d["objects"][1]["velocity"].pop(), r"objects\[1\]\.velocity: expected 91"),
        (lambda d: d["objects"][0].update(width="wide"), r"objects\[0\]\.width"),
        (lambda d: d["objects"][2]["position"][4].pop("y"), r"objects\[2\]\.position\[4\]\.y"),
        (lambda d: d["objects"][0]["valid"].__setitem__(3, "yes"), r"objects\[0\]\.valid"),
        (lambda d: d["roads"][0].pop("geometry"), r"roads\[0\]\.geometry"),
        (lambda d: d.update(roads=[r for r in d["roads"] if r["type"] != "lane"]), "no lane"),
        (lambda d: d["objects"][0].update(length=0.0), "positive"),
    ],
)
def test_bad_files_name_the_file_and_field(tmp_path, mutate, match):
    p = _straight(tmp_path)
    data = json.loads(p.read_text())
    mutate(data)
    p.write_text(json.dumps(data))
    with pytest.raises(MapError, match=match) as err:
        load_gpudrive_json(p)
    assert str(p) in str(err.value)


def test_unreadable_json(tmp_path):
    p = tmp_path / "broken.json"
    p.write_text('{"objects": [')
    with pytest.raises(MapError, match="not valid JSON") as err:
        load_gpudrive_json(p)
    assert "broken.json" in str(err.value)


def test_path_waypoints_spacing():
    path = np.c_[np.arange(0.0, 41.0), np.zeros(41)]  # 40 m
    wps, n = path_waypoints(path, 8, spacing=10.0)
    assert n == 4
    np.testing.assert_allclose(wps[:4, 0], [10, 20, 30, 40])
    np.testing.assert_allclose(wps[4:], np.tile([40.0, 0.0], (4, 1)))
    assert path_waypoints(path[:1], 8)[1] == 1  # a standing car: its position
    assert path_waypoints(np.zeros((0, 2)), 8)[1] == 0


def test_build_scenario_from_step_10(tmp_path):
    log = load_gpudrive_json(_straight(tmp_path))
    sc, lay = build_scenario(log)
    assert list(lay.agents) == [0, 1] and list(lay.statics) == [2] and list(lay.peds) == [3]
    np.testing.assert_allclose(sc.agent_xy[0], log.xy[0, 10], atol=1e-4)
    np.testing.assert_allclose(sc.agent_speed, [10.0, 8.0, 0.0], rtol=1e-6)
    # the last slot is the sentinel, parked outside the map and every observation radius
    assert np.all(sc.agent_xy[-1] > log.road_map.bounds[2:] + 400) and sc.agent_valid.all()
    # ego waypoints: its logged future (x = 1 .. 80 m), 10 m apart, last = final logged position
    assert sc.num_waypoints[0] == 8
    np.testing.assert_allclose(sc.waypoints[0, -1], log.xy[0, -1], atol=1e-3)
    assert np.all(np.abs(sc.waypoints[0, :, 1] - log.xy[0, 10, 1]) < 1e-4)
    assert sc.coeffs[0, 1] == 1.0 and sc.coeffs[0, 6] == 0.0  # evaluation vector (section 5)
    np.testing.assert_allclose(sc.static_xy[0], log.xy[2, 10], atol=1e-4)
    assert sc.ped_valid[0] and sc.ped_speed[0] == pytest.approx(1.2, rel=1e-3)
    assert sc.episode_length == pytest.approx(9.0)
    with pytest.raises(ValueError, match="start"):
        build_scenario(log, start=90)


def test_closed_loop_rule_based_ego_on_the_straight(tmp_path):
    log = load_gpudrive_json(_straight(tmp_path))
    rec, roll = run_logged(log, RuleBasedPolicy())
    assert rec.collided is False and rec.offroad is False and rec.kin_infeasible_any is False
    assert rec.progress_final > 0.8 and rec.log_ade_m < 8.0
    np.testing.assert_allclose(roll["ego_boxes"][:10, :2], log.xy[0, :10])  # history from the log
    assert roll["others"].shape == (T, 1 + 1 + 1, 5)  # lead (simulated), parked, pedestrian
    # the ego drives on along its lane (the rule-based agents go up to the 15 m/s limit)
    ego = roll["ego_boxes"][10:]
    assert ego[-1, 0] - ego[0, 0] > 60.0 and np.all(np.abs(ego[:, 1] - log.xy[0, 10, 1]) < 0.5)


def test_log_replay_of_the_other_agents(tmp_path):
    log = load_gpudrive_json(_straight(tmp_path))
    _, roll = run_logged(log, RuleBasedPolicy(), others="log")
    np.testing.assert_allclose(roll["others"][11:, 0, :2], log.xy[1, 11:], atol=1e-3)


def test_collision_and_offroad_are_detected(tmp_path):
    t = np.arange(T) * 0.1
    stopped = _obj(np.c_[np.full(T, 25.0), np.zeros(T)], 0.0, 0.0, oid=20)
    p = tmp_path / "blocked.json"
    data = json.loads(_straight(tmp_path).read_text())
    data["objects"][1] = stopped  # a car standing in the lane 25 m ahead of the ego
    p.write_text(json.dumps(data))
    rec, _ = run_logged(load_gpudrive_json(p), _constant(4.0))  # full throttle, no steering
    assert rec.collided is True
    bend = load_gpudrive_json(_bend(tmp_path))
    rec, _ = run_logged(bend, _constant(0.0))  # straight on at the bend
    assert rec.offroad is True and rec.progress_final < 0.8
    rec, _ = run_logged(bend, RuleBasedPolicy())
    assert rec.offroad is False and rec.collided is False and rec.progress_final > 0.8
    del t


def test_evaluate_logged_aggregates(tmp_path):
    files = [_straight(tmp_path), _bend(tmp_path)]
    res = evaluate_logged(files, RuleBasedPolicy())
    agg = res["aggregate"]
    assert agg["n_scenarios"] == 2 and len(res["records"]) == 2
    assert agg["collision_rate"].numerator == 0 and agg["offroad_rate"].denominator == 2
    assert agg["route_progress"].n == 2
