"""Waymax-style episode records and dataset aggregates (reference/metrics.md sections 1.8, 2.3).

One record per scenario for the controlled ego (the planning-benchmark convention, section 1.0):
collision and off-road are "at least once" over the rollout steps, ADE is the mean over steps,
progress is the final value, kinematic infeasibility is "any" plus the per-step fraction
(section 1.3 proposal). Dataset rates are plain means over scenarios with Wilson intervals.

Example:
    >>> import numpy as np
    >>> T = 12
    >>> xy = np.c_[np.arange(T) * 1.0, np.zeros(T)]
    >>> boxes = np.c_[xy, np.full(T, 4.0), np.full(T, 2.0), np.zeros(T)]
    >>> rec = waymax_episode(boxes, np.c_[np.full(T, 10.0), np.zeros(T)], xy, start=1)
    >>> rec.collided, rec.log_ade_m, rec.progress_final
    (False, 0.0, 1.0)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import NDArray

from selfplaydrive.eval.stats import MeanEstimate, Proportion, mean_estimate, proportion
from selfplaydrive.eval.waymax_metrics import (
    RoadEdges,
    boxes_overlap,
    kinematic_infeasibility,
    log_displacement,
    log_route_progress,
    offroad,
    path_length,
)

__all__ = ["AR_THRESHOLDS", "SUCCESS_PROGRESS", "WaymaxRecord", "aggregate_waymax", "waymax_episode"]

AR_THRESHOLDS = (0.75, 0.80, 0.85, 0.90, 0.95)  # LatentDriver mAR[75:95] (section 2.3)
SUCCESS_PROGRESS = 0.8  # our default "Score" success threshold (section 2.3 proposal)


@dataclass(frozen=True)
class WaymaxRecord:
    """The section 1.8 episode record of the ego in one scenario.

    Attributes:
        scenario_id: Label.
        collided: Ego overlapped a valid object at some rollout step.
        offroad: Some ego corner had signed road-edge distance > 0 (None = no road edges given).
        kin_infeasible_any: Some rollout transition was kinematically infeasible.
        kin_infeasible_frac: Share of valid rollout transitions that were infeasible.
        log_ade_m: Mean ego-to-log distance over valid rollout steps [m] (NaN = none valid).
        log_fde_m: Distance at the last step [m] (NaN if invalid there).
        progress_final: Log-trajectory progress at the last step (section 1.5 proposal).
        progress_max: Its maximum over the rollout.
        path_len_ego_m: Ego path length over the rollout [m].
        path_len_log_m: Logged ego path length over the same steps [m].
    """

    scenario_id: str
    collided: bool
    offroad: bool | None
    kin_infeasible_any: bool
    kin_infeasible_frac: float
    log_ade_m: float
    log_fde_m: float
    progress_final: float
    progress_max: float
    path_len_ego_m: float
    path_len_log_m: float

    def to_dict(self) -> dict[str, object]:
        """Plain dict of the record."""
        return asdict(self)


def _rollout_collision(
    ego: NDArray, valid: NDArray, others: NDArray | None, others_valid: NDArray | None
) -> NDArray:
    """(T,) bool: the ego overlaps some valid other object (section 1.1)."""
    if others is None or np.asarray(others).size == 0:
        return np.zeros(len(ego), dtype=bool)
    o = np.asarray(others, dtype=np.float64)
    ov = np.ones(o.shape[:2], dtype=bool) if others_valid is None else np.asarray(others_valid, dtype=bool)
    if o.ndim != 3 or o.shape[0] != len(ego) or ov.shape != o.shape[:2]:
        raise ValueError(
            f"others {o.shape} / others_valid {ov.shape}: expected (T={len(ego)}, N, 5) and (T, N)"
        )
    return np.any(boxes_overlap(ego[:, None, :], o) & ov, axis=1) & valid


def waymax_episode(
    ego_boxes: NDArray,
    ego_vel: NDArray,
    log_xy: NDArray,
    *,
    ego_valid: NDArray | None = None,
    log_valid: NDArray | None = None,
    others: NDArray | None = None,
    others_valid: NDArray | None = None,
    edges: RoadEdges | None = None,
    start: int = 10,
    dt: float = 0.1,
    scenario_id: str = "",
) -> WaymaxRecord:
    """Score one ego rollout against its log (sections 1.1–1.5, 1.7).

    Args:
        ego_boxes: (T, 5) simulated ego boxes (x, y, length, width, yaw) [m, rad].
        ego_vel: (T, 2) simulated ego velocity [m/s].
        log_xy: (T, 2) logged ego positions [m].
        ego_valid: (T,) simulated validity (default all valid).
        log_valid: (T,) logged validity (default all valid).
        others: (T, N, 5) boxes of every other object (collision partners), or None.
        others_valid: (T, N) their validity (default all valid).
        edges: Road edges for off-road, or None (off-road then None).
        start: Index of the "current" step; rollout steps are t > start (Waymax: 10).
        dt: Step length [s].
        scenario_id: Label.

    Returns:
        The `WaymaxRecord`.
    """
    ego = np.asarray(ego_boxes, dtype=np.float64)
    if ego.ndim != 2 or ego.shape[1] != 5:
        raise ValueError(f"ego_boxes has shape {ego.shape}: expected (T, 5)")
    T = len(ego)
    if not 0 <= start < T - 1:
        raise ValueError(f"start={start}: expected 0 ≤ start < T-1 = {T - 1} (need ≥ 1 rollout step)")
    ev = np.ones(T, dtype=bool) if ego_valid is None else np.asarray(ego_valid, dtype=bool)
    roll = np.arange(T) > start
    hit = _rollout_collision(ego, ev, others, others_valid)
    off = None if edges is None else bool(np.any(offroad(ego, edges) & ev & roll))
    kin, kin_ok = kinematic_infeasibility(ego_vel, ego[:, 4], ev, dt)
    kin_ok = kin_ok & roll
    d, d_ok = log_displacement(ego[:, :2], log_xy, ev, log_valid)
    d_ok = d_ok & roll
    prog = log_route_progress(ego[:, :2], log_xy, log_valid, start=start)[start + 1 :]
    return WaymaxRecord(
        scenario_id=scenario_id,
        collided=bool(np.any(hit & roll)),
        offroad=off,
        kin_infeasible_any=bool(np.any(kin & kin_ok)),
        kin_infeasible_frac=float(kin[kin_ok].mean()) if kin_ok.any() else math.nan,
        log_ade_m=float(d[d_ok].mean()) if d_ok.any() else math.nan,
        log_fde_m=float(d[-1]) if d_ok[-1] else math.nan,
        progress_final=float(prog[-1]),
        progress_max=float(np.nanmax(prog)) if np.isfinite(prog).any() else math.nan,
        path_len_ego_m=path_length(ego[:, :2], ev, start),
        path_len_log_m=path_length(log_xy, log_valid, start),
    )


def aggregate_waymax(records: Sequence[WaymaxRecord]) -> dict[str, Proportion | MeanEstimate | float | int]:
    """Dataset aggregates over scenarios (sections 1.0, 1.7, 2.3).

    Returns:
        ``offroad_rate``, ``collision_rate``, ``kinematic_infeasibility_rate``, ``success_rate``
        (no collision ∧ no off-road ∧ final progress ≥ 0.8) and ``ar_<τ>`` (∃t progress > τ ∧ no
        collision ∧ no off-road) as Wilson `Proportion`s over scenarios; ``mAR_75_95`` (float);
        ``log_ade_m``, ``log_fde_m``, ``route_progress`` as `MeanEstimate`s; ``total_driven_ratio``
        = ΣD_ego/ΣD_log and ``driven_ratio_median`` (scenarios with D_log ≥ 1 m) as floats.
    """
    n = len(records)
    clean = [r.collided is False and r.offroad is not True for r in records]
    res: dict[str, Proportion | MeanEstimate | float | int] = {"n_scenarios": n}
    known_off = [r.offroad for r in records if r.offroad is not None]
    res["offroad_rate"] = proportion(sum(known_off), len(known_off))
    res["collision_rate"] = proportion(sum(r.collided for r in records), n)
    res["kinematic_infeasibility_rate"] = proportion(sum(r.kin_infeasible_any for r in records), n)
    ok_prog = [c and r.progress_final >= SUCCESS_PROGRESS for c, r in zip(clean, records, strict=True)]
    res["success_rate"] = proportion(sum(ok_prog), n)
    ars = []
    for tau in AR_THRESHOLDS:
        ar = proportion(sum(c and r.progress_max > tau for c, r in zip(clean, records, strict=True)), n)
        res[f"ar_{round(tau * 100)}"] = ar
        ars.append(ar.value)
    res["mAR_75_95"] = float(np.mean(ars)) if n else math.nan
    means = (("log_ade_m", "log_ade_m"), ("log_fde_m", "log_fde_m"), ("route_progress", "progress_final"))
    for key, attr in means:
        res[key] = mean_estimate(np.array([getattr(r, attr) for r in records], dtype=float))
    d_ego = np.array([r.path_len_ego_m for r in records], dtype=float)
    d_log = np.array([r.path_len_log_m for r in records], dtype=float)
    res["total_driven_ratio"] = float(d_ego.sum() / d_log.sum()) if d_log.sum() > 0 else math.nan
    keep = d_log >= 1.0
    res["driven_ratio_median"] = float(np.median(d_ego[keep] / d_log[keep])) if keep.any() else math.nan
    return res
