"""Per agent-episode metrics and their aggregate against hand counts."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from selfplaydrive.eval.metrics import (
    EVENT_BITS,
    AgentEpisode,
    aggregate,
    aggregate_to_dict,
    count_onsets,
    episode_outcome,
)
from selfplaydrive.eval.stats import wilson_interval

T = 11


def _line(step_m: float = 100.0) -> np.ndarray:
    """11 positions 100 m apart along +x: 1.0 km over 10 transitions."""
    return np.c_[np.arange(T) * step_m, np.zeros(T)]


def _flags(*steps: int) -> np.ndarray:
    f = np.zeros(T, bool)
    f[list(steps)] = True
    return f


def _records() -> list[AgentEpisode]:
    """Four hand-made agent-episodes, 5.0 km in total."""
    invalid6 = np.ones(T, bool)
    invalid6[6] = False
    return [
        # 1 km, vehicle contact at steps 3–4 and again at 7 → 2 onsets; 3 of 4 waypoints
        AgentEpisode(_line(), vehicle_contact=_flags(3, 4, 7), waypoints_reached=3, waypoints_total=4),
        # 2 km (given), one road-edge contact, one red light lasting two steps; all 4 waypoints
        AgentEpisode(
            _line(),
            distance_m=2000.0,
            road_edge_contact=_flags(5),
            red_light=_flags(2, 3),
            waypoints_reached=4,
            waypoints_total=4,
        ),
        # 1 km, a pedestrian hit at step 1; no waypoints assigned (completion undefined)
        AgentEpisode(_line(), pedestrian_contact=_flags(1)),
        # 1 km, a vehicle contact at an invalid step does not count; 1 of 2 waypoints
        AgentEpisode(
            _line(),
            valid=invalid6,
            distance_m=1000.0,
            vehicle_contact=_flags(6),
            waypoints_reached=1,
            waypoints_total=2,
        ),
    ]


def test_count_onsets() -> None:
    assert count_onsets(np.array([1, 1, 0, 1, 0, 0, 1, 1], bool)) == 3
    assert count_onsets(np.array([], bool)) == 0
    # an invalid step in the middle of a contact splits it into two incidents
    assert count_onsets(np.array([1, 1, 1], bool), np.array([1, 0, 1], bool)) == 2


def test_episode_outcome_single() -> None:
    out = episode_outcome(_records()[0])
    assert out.collided_vehicle and not out.road_edge and not out.collided_pedestrian
    assert out.n_vehicle_collisions == 2
    assert out.km == pytest.approx(1.0)
    assert out.waypoint_completion == 0.75 and out.all_waypoints is False
    assert out.comfort_violation is None and out.kinematically_infeasible is None
    assert math.isnan(out.route_progress)


def test_km_skips_invalid_transitions() -> None:
    xy = _line()
    xy[5:] += [5000.0, 0.0]  # a teleport between steps 4 and 5 …
    valid = np.ones(T, bool)
    valid[5] = False  # … across an invalid step: transitions 4→5 and 5→6 are skipped
    assert episode_outcome(AgentEpisode(xy, valid=valid)).km == pytest.approx(0.8)


def test_aggregate_equals_hand_counts() -> None:
    agg = aggregate(_records())
    assert agg["n_agent_episodes"] == 4 and agg["km"] == pytest.approx(5.0)
    expected = {
        "collided_vehicle": (1, 4),
        "collided_pedestrian": (1, 4),
        "road_edge": (1, 4),
        "red_light": (1, 4),
        "collided_any": (2, 4),
        "incident_any": (3, 4),
        "all_waypoints": (1, 3),  # episode 3 has no waypoints, so the denominator is 3
        "comfort_violation": (0, 0),
    }
    for name, (k, n) in expected.items():
        p = agg[name]
        assert (p.numerator, p.denominator) == (k, n), name
        assert (p.lo, p.hi) == pytest.approx(wilson_interval(k, n)), name
    # onsets: vehicle 2, pedestrian 1, road edge 1 → 4 incidents; red light 1; waypoints 8
    assert agg["vehicle_collisions_per_km"].value == pytest.approx(2 / 5.0)
    assert agg["waypoints_per_km"].value == pytest.approx(8 / 5.0)
    assert agg["incidents_per_km"].numerator == 4 and agg["incidents_per_km"].denominator == 5.0
    assert agg["km_between_incidents"].value == pytest.approx(1.25)
    assert agg["km_between_incidents_incl_red"].value == pytest.approx(1.0)
    assert agg["km_between_red_light"].value == pytest.approx(5.0)
    assert agg["km_between_pedestrian_collisions"].incidents == 1
    # completion mean over the 3 episodes with waypoints: (0.75 + 1 + 0.5)/3 = 0.75
    wc = agg["waypoint_completion"]
    assert wc.value == pytest.approx(0.75) and wc.n == 3
    assert agg["route_progress"].n == 0
    json.dumps(aggregate_to_dict(agg), allow_nan=False)


def test_aggregate_accepts_outcomes_and_is_consistent() -> None:
    recs = _records()
    a = aggregate(recs)
    b = aggregate([episode_outcome(r) for r in recs])
    assert aggregate_to_dict(a) == aggregate_to_dict(b)


def test_comfort_from_accelerations_and_flags() -> None:
    a_long = np.zeros(T)
    a_long[2] = 3.5  # over the 3 m/s² limit
    a_long[4] = 3.0  # exactly at the limit: not a violation
    a_lat = np.zeros(T)
    a_lat[8] = -3.2
    out = episode_outcome(AgentEpisode(_line(), a_long=a_long, a_lat=a_lat))
    assert out.comfort_violation is True and out.comfort_step_fraction == pytest.approx(2 / 11)
    calm = episode_outcome(AgentEpisode(_line(), a_long=np.zeros(T), a_lat=np.full(T, 2.9)))
    assert calm.comfort_violation is False
    with pytest.raises(ValueError, match="both a_long and a_lat"):
        AgentEpisode(_line(), a_long=a_long)


def test_kinematics_through_episode() -> None:
    speed = np.full(T, 10.0)
    speed[6:] = 12.0  # +2 m/s in 0.1 s = 20 m/s² at step 6
    ep = AgentEpisode(_line(1.0), vel=np.c_[speed, np.zeros(T)], yaw=np.zeros(T))
    out = episode_outcome(ep)
    assert out.kinematically_infeasible is True and out.kin_infeasible_fraction == pytest.approx(1 / 10)
    agg = aggregate([ep, AgentEpisode(_line(1.0), vel=np.c_[np.full(T, 10.0), np.zeros(T)], yaw=np.zeros(T))])
    assert (agg["kinematically_infeasible"].numerator, agg["kinematically_infeasible"].denominator) == (1, 2)


def test_route_progress_ratio() -> None:
    out = episode_outcome(AgentEpisode(_line(), route_length_m=400.0, route_progress_m=300.0))
    assert out.route_progress == 0.75


def test_from_event_bits() -> None:
    ev = np.zeros(T, np.uint8)
    ev[1] = EVENT_BITS["vehicle"] | EVENT_BITS["road_edge"]
    ev[2] = EVENT_BITS["vehicle"]
    ev[4] = EVENT_BITS["red_light"]
    ev[5] = EVENT_BITS["comfort"]
    out = episode_outcome(AgentEpisode.from_event_bits(ev, _line()))
    assert (out.n_vehicle_collisions, out.n_road_edge, out.n_red_light) == (1, 1, 1)
    assert not out.collided_pedestrian and out.comfort_violation is True
    with pytest.raises(ValueError, match="integer bits"):
        AgentEpisode.from_event_bits(ev.astype(float), _line())


def test_bad_input_names_the_field() -> None:
    with pytest.raises(ValueError, match=r"'ep7': xy has shape \(11,\)"):
        AgentEpisode(np.zeros(T), episode_id="ep7")
    with pytest.raises(ValueError, match=r"vehicle_contact has shape \(3,\), expected \(11,\)"):
        AgentEpisode(_line(), vehicle_contact=np.zeros(3, bool))
    with pytest.raises(ValueError, match="waypoints_reached=5, waypoints_total=4"):
        AgentEpisode(_line(), waypoints_reached=5, waypoints_total=4)
    with pytest.raises(ValueError, match="distance_m=-1"):
        AgentEpisode(_line(), distance_m=-1.0)
