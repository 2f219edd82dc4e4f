"""Waymax-definition metrics on plain trajectories (reference/metrics.md section 1).

Implemented from the mathematical definitions in metrics.md, not from Waymax code (its licence
forbids porting, section 0). Every function takes NumPy arrays, so the same code scores our
simulator's rollouts and logged scenarios.

Boxes are rows ``(x, y, length, width, yaw)`` in [m, m, m, m, rad], world frame. Per-step
metrics follow Waymax's convention of a value and a validity mask per step and object
(section 1.0); episode reductions live in `selfplaydrive.eval.waymax_episode`.

Example:
    >>> import numpy as np
    >>> a = np.array([0.0, 0.0, 4.0, 2.0, 0.0])
    >>> b = np.array([3.9, 0.0, 4.0, 2.0, 0.0])
    >>> bool(boxes_overlap(a, b)), bool(boxes_overlap(a, b + [0.2, 0, 0, 0, 0]))
    (True, False)
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

__all__ = [
    "KIN_EPSILON",
    "MAX_ACCEL",
    "MAX_CURVATURE",
    "SPEED_LIMIT",
    "RoadEdges",
    "box_corners",
    "boxes_overlap",
    "inverse_bicycle",
    "kinematic_infeasibility",
    "log_displacement",
    "log_route_progress",
    "offroad",
    "overlap",
    "pairwise_overlap",
    "path_length",
    "path_progression",
    "signed_distance_to_road_edges",
]

# Waymax kinematic-infeasibility constants (metrics.md section 1.3).
MAX_ACCEL = 10.4  # [m/s²]
MAX_CURVATURE = 0.3  # [1/m]; Waymax calls it "steering" but it is a curvature
KIN_EPSILON = 1e-3
SPEED_LIMIT = 0.6  # [m/s] below which yaw comes from the record and curvature is 0

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


def _as_boxes(boxes: NDArray, name: str = "boxes") -> FloatArray:
    arr = np.asarray(boxes, dtype=np.float64)
    if arr.ndim == 0 or arr.shape[-1] != 5:
        raise ValueError(f"{name} has shape {arr.shape}: expected (..., 5) rows (x, y, length, width, yaw)")
    return arr


def box_corners(boxes: NDArray) -> FloatArray:
    """Corners of oriented boxes (metrics.md section 1.1).

    Args:
        boxes: (..., 5) rows (x, y, length, width, yaw) [m, m, m, m, rad].

    Returns:
        (..., 4, 2) corners in counter-clockwise order: front-left, rear-left, rear-right,
        front-right (the section 1.1 set, listed there from front-right).
    """
    b = _as_boxes(boxes)
    c, s = np.cos(b[..., 4]), np.sin(b[..., 4])
    l2, w2 = b[..., 2] / 2.0, b[..., 3] / 2.0
    # Local (±l, ±w) rotated by yaw, in the order of section 1.1.
    lx = np.stack([l2, -l2, -l2, l2], axis=-1)
    ly = np.stack([w2, w2, -w2, -w2], axis=-1)
    x = b[..., 0, None] + lx * c[..., None] - ly * s[..., None]
    y = b[..., 1, None] + lx * s[..., None] + ly * c[..., None]
    return np.stack([x, y], axis=-1)


def _axes(yaw: FloatArray) -> FloatArray:
    """(..., 2, 2) unit axes (heading, left normal) of boxes with yaw (...)."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.stack([np.stack([c, s], -1), np.stack([-s, c], -1)], axis=-2)


def boxes_overlap(a: NDArray, b: NDArray) -> BoolArray:
    """Separating-axis overlap test of oriented boxes (metrics.md section 1.1).

    On each of the 4 candidate axes (2 per box) the projected intervals must overlap with
    ``gap = min(maxA, maxB) − max(minA, minB) > 0`` strictly: touching boxes do not overlap.
    Computed in float64 (Waymax projects in float32; only exact-touching ties can differ).

    Args:
        a: (..., 5) boxes.
        b: (..., 5) boxes, broadcastable against `a`.

    Returns:
        (...) bool, True where the boxes overlap.
    """
    a, b = _as_boxes(a, "a"), _as_boxes(b, "b")
    ca, cb = box_corners(a), box_corners(b)  # (..., 4, 2)
    axes = np.concatenate(np.broadcast_arrays(_axes(a[..., 4]), _axes(b[..., 4])), axis=-2)  # (...,4,2)
    pa = np.einsum("...kd,...cd->...kc", axes, ca)  # (..., 4 axes, 4 corners)
    pb = np.einsum("...kd,...cd->...kc", axes, cb)
    gap = np.minimum(pa.max(-1), pb.max(-1)) - np.maximum(pa.min(-1), pb.min(-1))
    return np.all(gap > 0.0, axis=-1)


def pairwise_overlap(boxes: NDArray) -> BoolArray:
    """(N, N) overlap matrix of N boxes (N, 5), with a False diagonal."""
    b = _as_boxes(boxes)
    if b.ndim != 2:
        raise ValueError(f"boxes has shape {b.shape}: expected (N, 5)")
    m = boxes_overlap(b[:, None, :], b[None, :, :])
    np.fill_diagonal(m, False)
    return m


def overlap(boxes: NDArray, valid: NDArray) -> tuple[BoolArray, BoolArray]:
    """Per-step overlap of each object with any other valid object (metrics.md section 1.1).

    Args:
        boxes: (T, N, 5) boxes of N objects over T steps.
        valid: (T, N) bool validity.

    Returns:
        (value, valid), both (T, N): ``value[t, i] = valid[t, i] ∧ ∃ j ≠ i valid[t, j] ∧ overlap``.
    """
    b = _as_boxes(boxes)
    v = np.asarray(valid, dtype=bool)
    if b.ndim != 3 or v.shape != b.shape[:2]:
        raise ValueError(f"boxes {b.shape} / valid {v.shape}: expected (T, N, 5) and (T, N)")
    # Only pairs whose bounding circles (radius = half-diagonal) meet can overlap; running the
    # SAT test on those alone keeps 128 objects × 91 steps fast.
    radius = 0.5 * np.hypot(b[..., 2], b[..., 3])  # (T, N)
    dist = np.linalg.norm(b[:, :, None, :2] - b[:, None, :, :2], axis=-1)  # (T, N, N)
    cand = (dist < radius[:, :, None] + radius[:, None, :]) & v[:, :, None] & v[:, None, :]
    idx = np.arange(b.shape[1])
    cand[:, idx, idx] = False
    t, i, j = np.nonzero(cand)
    pair = np.zeros_like(cand)
    pair[t, i, j] = boxes_overlap(b[t, i], b[t, j])
    return np.any(pair, axis=-1), v.copy()


@dataclass(frozen=True)
class RoadEdges:
    """Road-edge samples in the Waymax roadgraph layout (metrics.md section 1.2).

    Attributes:
        xy: (P, 2) sample positions [m].
        dir: (P, 2) unit direction of each sample (towards the next sample of its polyline).
        ids: (P,) polyline id of each sample; consecutive samples of one polyline are adjacent.

    The drivable area must lie on the **left** of each directed polyline (section 1.2).
    """

    xy: FloatArray
    dir: FloatArray
    ids: NDArray[np.int64]
    _tree: cKDTree = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        xy = np.asarray(self.xy, dtype=np.float64)
        d = np.asarray(self.dir, dtype=np.float64)
        ids = np.asarray(self.ids, dtype=np.int64)
        if xy.ndim != 2 or xy.shape[1] != 2 or xy.shape[0] == 0:
            raise ValueError(f"RoadEdges.xy has shape {xy.shape}: expected (P, 2) with P ≥ 1")
        if d.shape != xy.shape or ids.shape != (xy.shape[0],):
            raise ValueError(f"RoadEdges.dir {d.shape} / ids {ids.shape}: expected {xy.shape} / ({len(xy)},)")
        if not np.isfinite(xy).all() or not np.isfinite(d).all():
            raise ValueError("RoadEdges.xy/dir contain NaN or inf")
        object.__setattr__(self, "xy", xy)
        object.__setattr__(self, "dir", d)
        object.__setattr__(self, "ids", ids)
        object.__setattr__(self, "_tree", cKDTree(xy))

    @classmethod
    def from_polylines(cls, polylines: list[NDArray], spacing: float = 0.5) -> RoadEdges:
        """Sample directed road-edge polylines every ≤ `spacing` [m] (WOMD samples ~0.5 m).

        Args:
            polylines: Each a (K, 2) array, K ≥ 2, drivable area on its left.
            spacing: Maximum distance between consecutive samples [m].

        Returns:
            `RoadEdges` with one id per polyline (its index in `polylines`).
        """
        if not spacing > 0.0:
            raise ValueError(f"spacing={spacing!r}: expected a positive sample spacing [m]")
        xs, ds, ids = [], [], []
        for i, line in enumerate(polylines):
            pts, dirs = _densify(np.asarray(line, dtype=np.float64), spacing, i)
            xs.append(pts)
            ds.append(dirs)
            ids.append(np.full(len(pts), i, dtype=np.int64))
        if not xs:
            raise ValueError("polylines is empty: off-road needs at least one road-edge polyline")
        return cls(np.concatenate(xs), np.concatenate(ds), np.concatenate(ids))


def _densify(line: FloatArray, spacing: float, index: int) -> tuple[FloatArray, FloatArray]:
    """Sample one polyline; repeated vertices are dropped so every direction is defined."""
    if line.ndim != 2 or line.shape[1] != 2:
        raise ValueError(f"road-edge polyline {index} has shape {line.shape}: expected (K, 2)")
    keep = np.ones(len(line), dtype=bool)
    keep[1:] = np.linalg.norm(np.diff(line, axis=0), axis=1) > 1e-9
    line = line[keep]
    if len(line) < 2:
        raise ValueError(f"road-edge polyline {index} has {len(line)} distinct point(s): expected ≥ 2")
    pts, dirs = [], []
    for a, b in itertools.pairwise(line):
        seg = b - a
        length = float(np.hypot(*seg))
        n = max(1, int(np.ceil(length / spacing)))
        f = np.arange(n)[:, None] / n
        pts.append(a + f * seg)
        dirs.append(np.repeat((seg / length)[None], n, axis=0))
    pts.append(line[-1:])
    dirs.append(dirs[-1][-1:])  # the last sample keeps the last segment's direction
    return np.concatenate(pts), np.concatenate(dirs)


def _cross(a: FloatArray, b: FloatArray) -> FloatArray:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def signed_distance_to_road_edges(points: NDArray, edges: RoadEdges) -> FloatArray:
    """Signed distance [m] to the nearest road-edge sample, > 0 off-road (metrics.md section 1.2).

    With k the nearest sample, ``χ_k = cross(c − p_k, d_k)`` and, when sample k−1 belongs to the
    same polyline, ``χ_{k−1} = cross(c − p_k, d_{k−1})``; the sign is that of χ_{k−1} if it is
    smaller than χ_k, else that of χ_k. 2-D only (our maps have no z, so no z-stretch).

    Args:
        points: (..., 2) query points [m].
        edges: Road-edge samples.

    Returns:
        (...) signed distance [m]; left of the directed edge (drivable side) is negative.
    """
    p = np.asarray(points, dtype=np.float64)
    if p.ndim == 0 or p.shape[-1] != 2:
        raise ValueError(f"points has shape {p.shape}: expected (..., 2)")
    flat = p.reshape(-1, 2)
    dist, k = edges._tree.query(flat)
    k = np.asarray(k, dtype=np.int64)
    rel = flat - edges.xy[k]
    chi_k = _cross(rel, edges.dir[k])
    prev = np.maximum(k - 1, 0)
    same = (k > 0) & (edges.ids[prev] == edges.ids[k])
    chi_prev = _cross(rel, edges.dir[prev])
    chi = np.where(same & (chi_prev < chi_k), chi_prev, chi_k)
    return (dist * np.sign(chi)).reshape(p.shape[:-1])


def offroad(boxes: NDArray, edges: RoadEdges) -> BoolArray:
    """Off-road flag per box: any corner with signed distance > 0 (metrics.md section 1.2).

    Args:
        boxes: (..., 5) boxes.
        edges: Road-edge samples.

    Returns:
        (...) bool. Waymax marks this metric always valid; mask by object validity yourself.
    """
    return np.any(signed_distance_to_road_edges(box_corners(boxes), edges) > 0.0, axis=-1)


def _wrap(angle: FloatArray) -> FloatArray:
    return (angle + np.pi) % (2.0 * np.pi) - np.pi


def inverse_bicycle(vel: NDArray, yaw: NDArray, dt: float = 0.1) -> tuple[FloatArray, FloatArray]:
    """Acceleration and curvature of each transition t−1 → t (metrics.md section 1.3).

    ``a = (v_t − v_{t−1})/dt``; heading ``ψ* = atan2(vy_t, vx_t)`` when ``v_t > 0.6`` else
    ``yaw_t``; ``κ = wrap(ψ* − yaw_{t−1}) / (v_{t−1}·dt + a·dt²/2)``, and 0 when either speed
    is below 0.6 m/s.

    Args:
        vel: (T, 2) velocity [m/s] (the state's velocity, not finite differences).
        yaw: (T,) heading [rad].
        dt: Step length [s].

    Returns:
        (accel, curvature), each (T−1,), in [m/s²] and [1/m].
    """
    v2 = np.asarray(vel, dtype=np.float64)
    psi = np.asarray(yaw, dtype=np.float64)
    if v2.ndim != 2 or v2.shape[1] != 2 or psi.shape != (len(v2),):
        raise ValueError(f"vel {v2.shape} / yaw {psi.shape}: expected (T, 2) and (T,)")
    if not dt > 0.0:
        raise ValueError(f"dt={dt!r}: expected a positive step length [s]")
    speed = np.hypot(v2[:, 0], v2[:, 1])
    accel = (speed[1:] - speed[:-1]) / dt
    head = np.where(speed[1:] > SPEED_LIMIT, np.arctan2(v2[1:, 1], v2[1:, 0]), psi[1:])
    dpsi = _wrap(head - _wrap(psi[:-1]))
    moving = (speed[:-1] >= SPEED_LIMIT) & (speed[1:] >= SPEED_LIMIT)
    travel = speed[:-1] * dt + 0.5 * accel * dt * dt
    curv = np.zeros_like(accel)
    curv[moving] = dpsi[moving] / travel[moving]
    return accel, curv


def kinematic_infeasibility(
    vel: NDArray,
    yaw: NDArray,
    valid: NDArray,
    dt: float = 0.1,
    max_accel: float = MAX_ACCEL,
    max_curvature: float = MAX_CURVATURE,
) -> tuple[BoolArray, BoolArray]:
    """Per-step kinematic infeasibility (metrics.md section 1.3).

    ``infeasible(t) = |a| > max_accel + 1e-3 ∨ |κ| > max_curvature + 1e-3`` for the transition
    t−1 → t, valid iff both states are valid. Step 0 has no transition and is invalid.

    Args:
        vel: (T, 2) velocity [m/s].
        yaw: (T,) heading [rad].
        valid: (T,) bool state validity.
        dt: Step length [s].
        max_accel: Acceleration bound [m/s²] (Waymax 10.4).
        max_curvature: Curvature bound [1/m] (Waymax 0.3).

    Returns:
        (value, valid), each (T,) bool.
    """
    ok = np.asarray(valid, dtype=bool)
    if ok.shape != (len(np.asarray(vel)),):
        raise ValueError(f"valid has shape {ok.shape}: expected ({len(np.asarray(vel))},)")
    accel, curv = inverse_bicycle(vel, yaw, dt)
    bad = (np.abs(accel) > max_accel + KIN_EPSILON) | (np.abs(curv) > max_curvature + KIN_EPSILON)
    step_valid = np.zeros_like(ok)
    step_valid[1:] = ok[1:] & ok[:-1]
    value = np.zeros_like(ok)
    value[1:] = bad
    return value & step_valid, step_valid


def _check_traj(xy: NDArray, valid: NDArray | None, name: str) -> tuple[FloatArray, BoolArray]:
    p = np.asarray(xy, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2:
        raise ValueError(f"{name} has shape {p.shape}: expected (T, 2) positions [m]")
    v = np.ones(len(p), dtype=bool) if valid is None else np.asarray(valid, dtype=bool)
    if v.shape != (len(p),):
        raise ValueError(f"{name} validity has shape {v.shape}: expected ({len(p)},)")
    return p, v


def log_displacement(
    sim_xy: NDArray, log_xy: NDArray, sim_valid: NDArray | None = None, log_valid: NDArray | None = None
) -> tuple[FloatArray, BoolArray]:
    """L2 distance [m] between simulated and logged positions per step (metrics.md section 1.4).

    Returns:
        (d, valid), each (T,); valid iff both the simulated and the logged state are valid.
    """
    s, sv = _check_traj(sim_xy, sim_valid, "sim_xy")
    g, gv = _check_traj(log_xy, log_valid, "log_xy")
    if len(s) != len(g):
        raise ValueError(f"sim_xy has {len(s)} steps but log_xy has {len(g)}: expected the same T")
    return np.linalg.norm(s - g, axis=1), sv & gv


def path_length(xy: NDArray, valid: NDArray | None = None, start: int = 0) -> float:
    """Driven length [m]: Σ ‖xy_t − xy_{t−1}‖ over t > start with both steps valid (section 1.7)."""
    p, v = _check_traj(xy, valid, "xy")
    step = np.linalg.norm(np.diff(p, axis=0), axis=1)
    both = v[1:] & v[:-1]
    both[: max(0, start)] = False  # transition index t−1 → t sits at t−1; keep t > start
    return float(step[both].sum())


def log_route_progress(
    sim_xy: NDArray,
    log_xy: NDArray,
    log_valid: NDArray | None = None,
    start: int = 10,
    min_length: float = 3.0,
) -> FloatArray:
    """Progress along the logged trajectory per step (metrics.md section 1.5, proposal).

    L = arc length of the valid log from `start` to the end; each simulated position is matched
    to its nearest valid log point k* (t ≥ start) and r = log arc length from k* to the end;
    ``progress = 1`` if ``L ≤ min_length`` or ``r ≤ min_length``, else ``(L − r)/L`` ∈ [0, 1].

    Returns:
        (T,) progress; NaN at steps before `start` and when the log has no valid point.
    """
    s, _ = _check_traj(sim_xy, None, "sim_xy")
    g, gv = _check_traj(log_xy, log_valid, "log_xy")
    out = np.full(len(s), np.nan)
    idx = np.flatnonzero(gv & (np.arange(len(g)) >= start))
    if idx.size == 0 or start >= len(s):
        return out
    pts = g[idx]
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    total = arc[-1]
    q = s[start:]
    k = np.argmin(np.linalg.norm(q[:, None, :] - pts[None, :, :], axis=-1), axis=1)
    remaining = total - arc[k]
    done = (total <= min_length) | (remaining <= min_length)
    prog = np.where(done, 1.0, (total - remaining) / max(total, 1e-12))
    out[start:] = prog
    return out


def path_progression(sim_xy: NDArray, log_start: NDArray, log_end: NDArray, path: NDArray) -> FloatArray:
    """Waymax-style progression along one on-route path (metrics.md section 1.5, steps 1–4).

    ``progress = (s(p) − s(p0)) / (s(pT) − s(p0))`` with s(q) the arc length at the path vertex
    nearest to q, p0/pT the logged start/end positions; 1.0 when s(pT) = s(p0). Not clipped:
    < 0 or > 1 are possible (the ego can drive past the logged end point).

    Args:
        sim_xy: (T, 2) simulated positions [m].
        log_start: (2,) logged position at t = 0 [m].
        log_end: (2,) logged position at the last step [m].
        path: (K, 2) on-route path vertices (densify first: s uses the nearest vertex).

    Returns:
        (T,) progression ratio.
    """
    s, _ = _check_traj(sim_xy, None, "sim_xy")
    pth, _ = _check_traj(path, None, "path")
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pth, axis=0), axis=1))])

    def s_of(q: FloatArray) -> FloatArray:
        return arc[np.argmin(np.linalg.norm(q[..., None, :] - pth, axis=-1), axis=-1)]

    s0 = s_of(np.asarray(log_start, dtype=np.float64))
    sT = s_of(np.asarray(log_end, dtype=np.float64))
    if sT == s0:
        return np.ones(len(s))
    return (s_of(s) - s0) / (sT - s0)
