"""Road-edge contact classification (`selfplaydrive.eval.edge_contacts`): hand-placed cars on a
hand-built road, and a car driven into the end of a dead-end lane."""

from __future__ import annotations

import numpy as np
import pytest

from selfplaydrive.eval.edge_contacts import (
    CATEGORIES,
    EdgeContactRecorder,
    MapGeometry,
    classify_onset,
    edge_contacts,
)
from selfplaydrive.eval.suites.base import FixedScenarioSpawner, blank_scenario, put_agent
from selfplaydrive.maps.compile import compile_map
from selfplaydrive.maps.elements import LaneElement, MapElements, PolylineElement
from selfplaydrive.sim import VecEnv
from selfplaydrive.sim.actions import ContinuousActions

HALF = 1.75  # [m] half the lane width


def dead_end_road():
    """Lanes 0 -> 1 -> 3 along y = 0 (x 0..60, a junction lane 60..70, 70..100; lane 3 ends the
    map, open); lane 2: a dead end, x 0..60 along y = 20, its drivable area closed by an edge
    across x = 60."""
    lanes = [
        LaneElement(np.array([[0.0, 0.0], [60.0, 0.0]]), 2 * HALF, 14.0, successors=[1]),
        LaneElement(np.array([[60.0, 0.0], [70.0, 0.0]]), 2 * HALF, 14.0, successors=[3], in_junction=True),
        LaneElement(np.array([[0.0, 20.0], [60.0, 20.0]]), 2 * HALF, 14.0),
        LaneElement(np.array([[70.0, 0.0], [100.0, 0.0]]), 2 * HALF, 14.0),
    ]
    edges = [np.array([[0.0, y], [100.0, y]]) for y in (-HALF, HALF)] + [
        np.array([[0.0, 20.0 + s], [60.0, 20.0 + s]]) for s in (-HALF, HALF)
    ]
    edges.append(np.array([[60.0, 20.0 - HALF], [60.0, 20.0 + HALF]]))
    return compile_map(
        MapElements(
            name="dead_end_road",
            source="tests/eval/test_edge_contacts.py",
            lanes=lanes,
            road_edges=[PolylineElement(e) for e in edges],
        )
    )


@pytest.fixture(scope="module")
def road():
    return dead_end_road()


def local(road_map, x, y):
    """Source coordinates -> the compiled map's local frame (lane 0 starts at source (0, 0))."""
    return road_map.lanes.centerlines[0][0].astype(np.float64) + np.array([x, y])


def test_geometry_reads_the_lane_graph(road):
    g = MapGeometry.of(road)
    assert g.dead_end.tolist() == [False, False, True, True]
    assert g.in_junction.tolist() == [False, True, False, False]
    np.testing.assert_allclose(g.lane_end[2], local(road, 60.0, 20.0), atol=1e-4)


@pytest.mark.parametrize(
    ("x", "y", "heading_deg", "expected"),
    [
        (57.0, 20.0, 0.0, "dead_end"),  # at the closed end of lane 2
        (45.0, 20.0, 0.0, "along"),  # 15 m before it: farther than end_radius (10 m)
        (30.0, 1.0, 90.0, "crossing"),  # driving straight at lane 0's left edge
        (30.0, 1.0, 10.0, "along"),  # drifting into it
        (64.0, 1.0, 0.0, "junction"),  # on the junction lane, along its edge
        (57.0, 0.0, 0.0, "along"),  # lane 0 has a successor: its end is no dead end
    ],
)
def test_classify_hand_placed_cars(road, x, y, heading_deg, expected):
    g = MapGeometry.of(road)
    got = classify_onset(g, local(road, x, y), np.radians(heading_deg))
    assert got == expected


def dead_end_env(road):
    """Car 0 at 10 m/s, centre at x = 40 on lane 2, heading for its closed end; car 1 stands on
    lane 0, so that the world does not restart (and clear its event bits) when car 0 ends."""
    start = local(road, 40.0, 20.0)
    sc = blank_scenario(road, 0, start, 10.0)
    put_agent(sc, 0, start, 0.0, 10.0, (4.5, 2.0), 2, np.array([local(road, 55.0, 20.0)]))
    put_agent(sc, 1, local(road, 10.0, 0.0), 0.0, 0.0, (4.5, 2.0), 0, np.array([local(road, 50.0, 0.0)]))
    return VecEnv(road, FixedScenarioSpawner([sc]), 1, actions=ContinuousActions()), start


def test_a_car_driven_into_a_dead_end_is_counted_once_there(road):
    # A 4.5 m car at 10 m/s, centre at x = 40 on lane 2: its front reaches the closing edge at
    # x = 60 when the centre is at 57.75, after 17.75 m = 1.775 s, i.e. on step 18 (dt 0.1 s).
    env, start = dead_end_env(road)
    env.reset(0)
    recorder = EdgeContactRecorder(env)
    first = None
    for step in range(1, 31):
        env.step(np.zeros((env.num_agents, 2), np.float32))
        recorder.record()
        if first is None and recorder.result.total:
            first = step
    assert recorder.result.counts == {"dead_end": 1, "crossing": 0, "junction": 0, "along": 0}
    assert first in (18, 19)  # the contact test's rounding of the box against the segment
    name, m, x, *_ = recorder.result.onsets[0]
    assert (name, m) == ("dead_end", 0)
    assert x == pytest.approx(start[0] + 10.0 * 0.1 * first, abs=0.5)
    summary = recorder.result.to_dict()
    assert summary["onsets"] == 1 and summary["categories"]["dead_end"]["share"] == 1.0
    assert set(summary["categories"]) == set(CATEGORIES)


def test_edge_contacts_drives_a_policy(road):
    env, _ = dead_end_env(road)
    table = edge_contacts(env, lambda obs, e: np.zeros((e.num_agents, 2), np.float32), steps=25, seed=0)
    assert table.counts["dead_end"] == 1 and table.total == 1
    assert table.agent_steps in (25 + 18, 25 + 19)  # car 1 every step, car 0 up to its contact
    assert "| dead_end | 1 | 100.0 % |" in table.markdown()


def test_bad_arguments_are_named(road):
    sc = blank_scenario(road, 0, local(road, 10.0, 0.0), 10.0)
    put_agent(sc, 0, local(road, 10.0, 0.0), 0.0, 5.0, (4.5, 2.0), 0, np.array([local(road, 30.0, 0.0)]))
    env = VecEnv(road, FixedScenarioSpawner([sc]), 1, actions=ContinuousActions())
    with pytest.raises(ValueError, match="crossing_deg=95"):
        EdgeContactRecorder(env, crossing_deg=95)
    with pytest.raises(ValueError, match="steps: expected >= 1"):
        edge_contacts(env, lambda obs, e: np.zeros((e.num_agents, 2), np.float32), steps=0)
