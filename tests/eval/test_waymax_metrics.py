"""Waymax-definition metrics on hand-built geometry (reference/metrics.md section 1)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from selfplaydrive.eval.waymax_episode import aggregate_waymax, waymax_episode
from selfplaydrive.eval.waymax_metrics import (
    RoadEdges,
    box_corners,
    boxes_overlap,
    inverse_bicycle,
    kinematic_infeasibility,
    log_displacement,
    log_route_progress,
    offroad,
    overlap,
    pairwise_overlap,
    path_length,
    path_progression,
    signed_distance_to_road_edges,
)

CAR = np.array([0.0, 0.0, 4.0, 2.0, 0.0])  # 4 m × 2 m at the origin facing +x


def _box(x: float, y: float, yaw: float = 0.0, length: float = 4.0, width: float = 2.0) -> np.ndarray:
    return np.array([x, y, length, width, yaw])


# ---------------------------------------------------------------- boxes (section 1.1)


def test_corners_axis_aligned_and_rotated() -> None:
    np.testing.assert_allclose(box_corners(CAR), [[2, 1], [-2, 1], [-2, -1], [2, -1]])
    # yaw = 90°: front-left (l, w) = (2, 1) rotates to (−1, 2)
    np.testing.assert_allclose(box_corners(_box(1, 1, math.pi / 2))[0], [0.0, 3.0], atol=1e-12)


def test_overlap_touching_separated() -> None:
    assert boxes_overlap(CAR, _box(3.0, 0.0))  # x-intervals [−2,2] and [1,5]: gap 1 m
    assert not boxes_overlap(CAR, _box(4.0, 0.0))  # touching: gap exactly 0 → no overlap
    assert not boxes_overlap(CAR, _box(5.0, 0.0))  # 1 m apart
    assert not boxes_overlap(CAR, _box(0.0, 2.0))  # touching side by side
    assert boxes_overlap(CAR, _box(0.0, 1.9))


def test_overlap_rotated() -> None:
    # 2 × 2 square rotated 45°: its half-diagonal is √2, so its left vertex is at x = cx − √2.
    r2 = math.sqrt(2.0)
    assert boxes_overlap(CAR, _box(2.0 + r2 - 0.05, 0.0, math.pi / 4, 2.0, 2.0))
    assert not boxes_overlap(CAR, _box(2.0 + r2 + 0.05, 0.0, math.pi / 4, 2.0, 2.0))
    # Two parallel 10 × 1 bars along y = x, 5/√2 = 3.54 m apart: their axis-aligned bounding
    # boxes overlap, only the bars' own normal separates them.
    a, b = _box(0, 0, math.pi / 4, 10, 1), _box(2.5, -2.5, math.pi / 4, 10, 1)
    ca, cb = box_corners(a), box_corners(b)
    assert ca[:, 0].max() > cb[:, 0].min() and ca[:, 1].min() < cb[:, 1].max()  # AABBs overlap
    assert not boxes_overlap(a, b)
    assert boxes_overlap(a, _box(0.5, -0.5, math.pi / 4, 10, 1))  # 0.71 m apart < 1 m width


def test_pairwise_and_per_step_validity() -> None:
    boxes = np.stack([CAR, _box(3, 0), _box(20, 0)])
    m = pairwise_overlap(boxes)
    assert m.tolist() == [[False, True, False], [True, False, False], [False, False, False]]
    # Partner 1 invalid at step 1: object 0 overlaps only at step 0; invalid objects never do.
    T = np.stack([boxes, boxes])
    valid = np.array([[True, True, True], [True, False, True]])
    hit, ok = overlap(T, valid)
    assert hit.tolist() == [[True, True, False], [False, False, False]]
    assert ok.tolist() == valid.tolist()
    with pytest.raises(ValueError, match=r"expected \(T, N, 5\)"):
        overlap(boxes, valid)


def test_overlap_prefilter_matches_brute_force() -> None:
    # The bounding-circle prefilter must not drop any pair that the plain SAT test finds.
    rng = np.random.default_rng(3)
    T, N = 6, 40
    xy, yaw = rng.uniform(0, 25, (T, N, 2)), rng.uniform(-3, 3, (T, N, 1))
    size = np.concatenate([rng.uniform(1, 6, (T, N, 1)), rng.uniform(0.5, 2.5, (T, N, 1))], axis=-1)
    boxes = np.concatenate([xy, size, yaw], axis=-1)
    valid = rng.random((T, N)) > 0.1
    pair = boxes_overlap(boxes[:, :, None, :], boxes[:, None, :, :])
    pair[:, np.arange(N), np.arange(N)] = False
    ref = np.any(pair & valid[:, None, :], axis=-1) & valid
    hit, _ = overlap(boxes, valid)
    assert ref.sum() > 20  # dense enough to be a real check
    assert np.array_equal(hit, ref)


# ---------------------------------------------------------------- off-road (section 1.2)

SQUARE_CCW = np.array([[0, 0], [20, 0], [20, 20], [0, 20], [0, 0]], dtype=float)


def test_signed_distance_square() -> None:
    edges = RoadEdges.from_polylines([SQUARE_CCW], spacing=0.5)
    d = signed_distance_to_road_edges(np.array([[10, 10], [10, 3], [30, 10], [10, -2], [21, -1]]), edges)
    # inside: −distance to the nearest edge; outside: +distance (corner (21,−1) is √2 from (20,0))
    np.testing.assert_allclose(d, [-10, -3, 10, 2, math.sqrt(2)], atol=1e-9)


def test_offroad_box_in_square() -> None:
    edges = RoadEdges.from_polylines([SQUARE_CCW])
    assert not offroad(_box(10, 10), edges)
    assert not offroad(_box(10, 10, 0.7), edges)
    assert offroad(_box(1, 10), edges)  # rear corners at x = −1
    assert offroad(_box(30, 10), edges)  # fully outside
    assert offroad(_box(10, 19.5, math.pi / 2), edges)  # nose 1.5 m through the top edge
    # Reversed (clockwise) edge: the inside is now off-road, the Waymax convention.
    cw = RoadEdges.from_polylines([SQUARE_CCW[::-1]])
    assert offroad(_box(10, 10), cw)
    batch = offroad(np.stack([_box(10, 10), _box(30, 10)]), edges)
    assert batch.tolist() == [False, True]


def test_road_edges_bad_input() -> None:
    with pytest.raises(ValueError, match="polyline 0 has 1 distinct point"):
        RoadEdges.from_polylines([np.array([[1.0, 1.0], [1.0, 1.0]])])
    with pytest.raises(ValueError, match="polylines is empty"):
        RoadEdges.from_polylines([])
    with pytest.raises(ValueError, match="spacing=0"):
        RoadEdges.from_polylines([SQUARE_CCW], spacing=0)


# ---------------------------------------------------------------- kinematics (section 1.3)


def _straight(T: int, speed: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    v = np.broadcast_to(np.asarray(speed, dtype=float), (T,))
    return np.c_[v, np.zeros(T)], np.zeros(T)


def test_feasible_straight() -> None:
    vel, yaw = _straight(20, 10.0)
    bad, ok = kinematic_infeasibility(vel, yaw, np.ones(20, bool))
    assert not bad.any()
    assert ok.tolist() == [False] + [True] * 19  # step 0 has no transition


def test_impossible_acceleration() -> None:
    # 10 → 12 m/s in 0.1 s: a = 20 m/s² > 10.4 at step 3 only
    speed = np.array([10, 10, 10, 12, 12, 12.0])
    vel, yaw = _straight(6, speed)
    bad, _ = kinematic_infeasibility(vel, yaw, np.ones(6, bool))
    assert np.flatnonzero(bad).tolist() == [3]
    # Bound + ε: a = 10.4 is feasible, a = 10.41 is not (1e-3 tolerance).
    for dv, expect in ((1.04, False), (1.041, True)):
        vel, yaw = _straight(2, np.array([10.0, 10.0 + dv]))
        assert bool(kinematic_infeasibility(vel, yaw, np.ones(2, bool))[0][1]) is expect
    # invalid neighbour masks the transition
    vel, yaw = _straight(6, speed)
    bad, ok = kinematic_infeasibility(vel, yaw, np.array([1, 1, 0, 1, 1, 1], bool))
    assert not bad[3] and not ok[3]


def test_curvature_from_inverse_bicycle() -> None:
    # v = 10 m/s, heading turns by Δψ in one step: κ = Δψ / (10·0.1) = Δψ [1/m]
    for dpsi, expect in ((0.05, False), (0.4, True)):
        yaw = np.array([0.0, dpsi])
        vel = 10.0 * np.c_[np.cos(yaw), np.sin(yaw)]
        acc, curv = inverse_bicycle(vel, yaw)
        assert acc[0] == pytest.approx(0.0, abs=1e-9) and curv[0] == pytest.approx(dpsi)
        assert bool(kinematic_infeasibility(vel, yaw, np.ones(2, bool))[0][1]) is expect
    # below 0.6 m/s the curvature is set to 0 whatever the yaw does
    yaw = np.array([0.0, 3.0])
    vel = 0.5 * np.c_[np.cos(yaw), np.sin(yaw)]
    assert inverse_bicycle(vel, yaw)[1][0] == 0.0


# ---------------------------------------------------------------- ADE, progress (1.4, 1.5, 1.7)


def test_ade_of_shifted_trajectory() -> None:
    log = np.c_[np.arange(10.0), np.zeros(10)]
    d, ok = log_displacement(log + np.array([3.0, 4.0]), log)
    assert np.allclose(d, 5.0) and ok.all()  # 3-4-5 triangle
    sim_valid = np.ones(10, bool)
    sim_valid[4] = False
    _, ok = log_displacement(log + np.array([3.0, 4.0]), log, sim_valid)
    assert ok.sum() == 9
    with pytest.raises(ValueError, match="sim_xy has 9 steps but log_xy has 10"):
        log_displacement(log[:9], log)


def test_route_progress_straight() -> None:
    log = np.c_[np.arange(11) * 10.0, np.zeros(11)]  # 0 … 100 m
    sim = log.copy()
    sim[-1] = [50.0, 0.5]  # nearest log point x = 50 (k* = 5): r = 50, (100 − 50)/100
    sim[5] = [8.0, 0.0]  # nearest x = 10: r = 90 → 0.1
    prog = log_route_progress(sim, log, start=0)
    assert prog[-1] == pytest.approx(0.5) and prog[5] == pytest.approx(0.1)
    sim[-1] = [98.5, 0.0]  # r = 0 ≤ 3 m → 1
    assert log_route_progress(sim, log, start=0)[-1] == 1.0
    assert np.isnan(log_route_progress(sim, log, start=3)[:3]).all()
    # a log shorter than 3 m counts as complete
    assert log_route_progress(sim, log * 0.01, start=0)[0] == 1.0


def test_path_progression_unclipped_and_path_length() -> None:
    path = np.c_[np.arange(201.0), np.zeros(201)]  # 200 m, 1 m vertices
    sim = np.array([[0.0, 0.0], [50.0, 1.0], [150.0, 0.0]])
    prog = path_progression(sim, np.array([0.0, 0.0]), np.array([100.0, 0.0]), path)
    np.testing.assert_allclose(prog, [0.0, 0.5, 1.5])
    xy = np.array([[0, 0], [3, 4], [6, 8], [100, 100], [103, 104.0]])
    assert path_length(xy) == pytest.approx(5 + 5 + math.hypot(94, 92) + 5)
    assert path_length(xy, np.array([1, 1, 1, 0, 1], bool)) == pytest.approx(10.0)
    assert path_length(xy, start=1) == pytest.approx(5 + math.hypot(94, 92) + 5)


# ---------------------------------------------------------------- episode record (1.8)


def test_waymax_episode_and_aggregate() -> None:
    T, start = 16, 5
    xy = np.c_[np.arange(T) * 1.0, np.zeros(T)]  # 10 m/s at dt = 0.1
    ego = np.c_[xy, np.full(T, 4.0), np.full(T, 2.0), np.zeros(T)]
    vel = np.c_[np.full(T, 10.0), np.zeros(T)]
    other = np.tile(_box(100.0, 0.0), (T, 1))
    other[2] = _box(2.0, 0.0)  # overlap during history (t ≤ start) does not count
    rec0 = waymax_episode(ego, vel, xy, others=other[:, None, :], start=start, scenario_id="a")
    assert not rec0.collided and not rec0.kin_infeasible_any and rec0.offroad is None
    assert rec0.log_ade_m == 0.0 and rec0.progress_final == 1.0
    assert rec0.path_len_ego_m == pytest.approx(10.0)  # 10 transitions of 1 m after t = 5
    other[9] = _box(9.0, 1.5)  # overlaps at rollout step 9
    shifted = xy + np.array([0.0, 1.0])
    rec1 = waymax_episode(ego, vel, shifted, others=other[:, None, :], start=start, scenario_id="b")
    assert rec1.collided and rec1.log_ade_m == pytest.approx(1.0) and rec1.log_fde_m == pytest.approx(1.0)
    agg = aggregate_waymax([rec0, rec1])
    assert agg["collision_rate"].numerator == 1 and agg["collision_rate"].denominator == 2
    assert agg["offroad_rate"].denominator == 0  # no road edges given
    assert agg["success_rate"].numerator == 1 and agg["mAR_75_95"] == pytest.approx(0.5)
    assert agg["log_ade_m"].value == pytest.approx(0.5) and agg["total_driven_ratio"] == pytest.approx(1.0)
    edges = RoadEdges.from_polylines([np.array([[-10, -3], [30, -3.0]]), np.array([[30, 3], [-10, 3.0]])])
    assert waymax_episode(ego, vel, xy, edges=edges, start=start).offroad is False
    with pytest.raises(ValueError, match="start=15"):
        waymax_episode(ego, vel, xy, start=15)
