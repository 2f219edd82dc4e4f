"""Vehicle collisions classified by partner and geometry (`selfplaydrive.eval.collisions`)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from fakeenv import one_world_env

from selfplaydrive.eval.collisions import KINDS, CollisionBreakdown, CollisionRecorder, geometry
from selfplaydrive.maps.compile import compile_map
from selfplaydrive.maps.elements import LaneElement, MapElements


def straight_road():
    """Lanes along y = 0 heading +x: 0 (x -50..150) -> 1 (150..250, a junction lane) -> 2
    (250..1000)."""
    xs = [(-50.0, 150.0, False), (150.0, 250.0, True), (250.0, 1000.0, False)]
    lanes = [
        LaneElement(np.array([[a, 0.0], [b, 0.0]]), 3.5, 14.0, successors=[k + 1][: 2 - k], in_junction=j)
        for k, (a, b, j) in enumerate(xs)
    ]
    return compile_map(MapElements(name="straight", source="tests/eval/test_collisions.py", lanes=lanes))


@pytest.mark.parametrize(
    ("a", "b", "kind"),
    [
        (0.0, 0.0, "rear_end"),
        (0.0, 0.5, "rear_end"),  # the bound belongs to rear_end
        (3.0, -3.0, "rear_end"),  # 0.28 rad across the +-pi wrap
        (0.0, np.pi / 2, "crossing"),
        (0.0, 2.5, "crossing"),
        (0.0, 2.6, "head_on"),
        (np.pi / 2, -np.pi / 2, "head_on"),
    ],
)
def test_geometry_from_headings(a, b, kind):
    assert geometry(a, b) == kind


def _fake_env() -> SimpleNamespace:
    """One world on `straight_road` (positions below in source coordinates), 8 agent slots, 1
    static vehicle. Pairs that overlap: 0-1 head-on (headings 0 and pi), 2-3 rear-end (3
    stands), 4-5 crossing, on the junction lane (x 150..250); 6 overlaps the static vehicle;
    7 is alone."""
    env = one_world_env(
        (303.0, 1.0),
        events=np.array([1, 1, 1, 1, 1, 1, 1, 0], np.uint8),
        x=np.array([0.0, 4.0, 100.0, 104.0, 200.0, 202.0, 300.0, 900.0], np.float32),
        y=np.array([0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0], np.float32),
        heading=np.array([0.0, np.pi, 0.0, 0.0, 0.0, np.pi / 2, 0.0, 0.0], np.float32),
        speed=np.array([8.0, 6.0, 9.0, 0.0, 5.0, 7.0, 3.0, 10.0], np.float32),
        lane_valid=np.array([1, 1, 1, 1, 1, 0, 1, 1], np.uint8),
        lane_alpha=np.array([0.0, 0.1, 0.0, 0.0, 1.2, 0.0, 0.05, 0.0], np.float32),
        lane_s=np.array([0.9, -0.8, 0.2, 0.1, 0.3, 0.0, 1.4, 0.0], np.float32),
    )
    road = straight_road()
    origin = road.lanes.centerlines[0][0].astype(np.float64) + np.array([50.0, 0.0])  # source (0, 0)
    st = env.state
    st.x, st.y = (st.x + origin[0]).astype(np.float32), (st.y + origin[1]).astype(np.float32)
    st.st_x, st.st_y = (st.st_x + origin[0]).astype(np.float32), (st.st_y + origin[1]).astype(np.float32)
    st.map_id = np.zeros(1, np.int32)
    env.maps = [road]
    return env


def test_recorder_classifies_constructed_contacts():
    env = _fake_env()
    rec = CollisionRecorder(env)
    rec.record()
    rec.record()  # the contacts persist: no new onsets
    b = rec.breakdown()
    # one row per agent pair (from the lower slot), one for the static contact
    assert b.kind.tolist() == ["head_on", "rear_end", "crossing", "static"]
    np.testing.assert_allclose(b.speed, [8.0, 9.0, 7.0, 3.0])  # the faster of the two
    assert b.stopped.tolist() == [False, True, False, False]
    # agent 4 is 1.2 rad off its lane (> 60 deg: no offset), agent 5 has no lane, statics none
    np.testing.assert_allclose(b.ego_offset, [0.9, 0.2, np.nan, 1.4], rtol=1e-6)
    np.testing.assert_allclose(b.partner_offset, [0.8, 0.1, np.nan, np.nan], rtol=1e-6)
    assert b.overlap.all()
    # only 4 (heading +x at x = 200) is on the junction lane; 1 and 5 head against every lane
    assert b.junction.tolist() == [False, False, True, False]
    d = b.to_dict()
    assert d["collisions"] == 4 and sum(d[k]["count"] for k in KINDS) == 4
    assert d["head_on"]["share"] == 0.25 and d["rear_end"]["share_stopped"] == 1.0
    assert np.isnan(d["crossing"]["median_ego_offset"])
    md = b.markdown()
    assert d["crossing"]["share_junction"] == 1.0 and d["head_on"]["share_junction"] == 0.0
    assert "| head_on | 1 | 25.0 % | 8.0 | 0.90 / 0.80 | 0 % | 0 % |" in md
    assert "| crossing | 1 | 25.0 % | 7.0 | - / - | 0 % | 100 % |" in md


def test_an_onset_of_an_agent_that_did_not_act_is_ignored():
    env = _fake_env()
    env.reward_mask[:] = False
    env.reward_mask[6] = True  # only the static contact counts
    rec = CollisionRecorder(env)
    rec.record()
    assert rec.breakdown().kind.tolist() == ["static"]


def test_bad_settings_and_shapes_are_refused():
    with pytest.raises(ValueError, match=r"crossing_rad=2\.0, head_on_rad=1\.0"):
        CollisionRecorder(_fake_env(), crossing_rad=2.0, head_on_rad=1.0)
    with pytest.raises(ValueError, match="speed: expected 1 entries"):
        CollisionBreakdown(kind=np.array(["static"]))
    with pytest.raises(ValueError, match=r"unknown kinds \['side'\]"):
        z = np.zeros(1)
        CollisionBreakdown(
            kind=np.array(["side"]), speed=z, ego_offset=z, partner_offset=z, stopped=z, overlap=z, junction=z
        )
    assert CollisionBreakdown().to_dict()["collisions"] == 0


def test_the_simulator_s_contacts_are_classified():
    """Three pairs placed far from the map on the default town, 0.5 m apart (bumper to bumper or
    to side) with the striking car at 10 m/s, driven one step straight at constant speed: each
    pair touches in the simulator and is logged with its geometry."""
    from selfplaydrive import make_env

    env = make_env("default", num_worlds=1, seed=4)
    env.reset(seed=4)
    L = env.state.length[:6].astype(np.float64)
    W = env.state.width[:6].astype(np.float64)
    gap = 0.5
    # 0 drives east into 1 driving west; 2 east behind 3 standing; 4 east into 5's side (north)
    xy = np.array(
        [
            [5000.0, 5000.0],
            [5000.0 + (L[0] + L[1]) / 2 + gap, 5000.0],
            [6000.0, 5000.0],
            [6000.0 + (L[2] + L[3]) / 2 + gap, 5000.0],
            [7000.0, 5000.0],
            [7000.0 + L[4] / 2 + W[5] / 2 + gap, 5000.0],
        ]
    )
    env.set_poses(
        range(6),
        xy,
        np.array([0.0, np.pi, 0.0, 0.0, 0.0, np.pi / 2]),
        np.array([10.0, 10.0, 10.0, 0.0, 10.0, 0.0]),
    )
    acts = np.zeros((env.num_agents, 2), np.int64)
    t = env.action_table
    acts[:, 0] = int(np.argmin(np.abs(t.accel)))
    acts[:, 1] = int(np.argmin(np.abs(t.steer)))
    rec = CollisionRecorder(env)
    env.step(acts)
    rec.record()
    assert np.all(env.state.events[:6] & 1), "the constructed pairs must touch in the simulator"
    b = rec.breakdown()
    assert sorted(b.kind.tolist()) == ["crossing", "head_on", "rear_end"]
    # 3 and 5 stand, so only the head-on pair has both moving
    assert b.stopped.tolist() == [k != "head_on" for k in b.kind]
