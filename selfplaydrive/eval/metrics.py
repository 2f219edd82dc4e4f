"""Per agent-episode metrics of self-play evaluation and their aggregates.

Inputs are plain arrays (an `AgentEpisode` per agent and episode), so the same code scores
the simulator's rollouts, logged scenarios and hand-made test cases. Definitions follow
reference/metrics.md: incidents are edge-triggered contacts (section 2.4), comfort uses the
paper's 3 m/s² limit (paper section 2.3), kinematic infeasibility uses Waymax's bounds
(section 1.3), and every aggregate carries its denominator and a 95 % interval (section 9).

Example:
    >>> import numpy as np
    >>> T = 4
    >>> ep = AgentEpisode(
    ...     xy=np.c_[np.arange(T) * 10.0, np.zeros(T)],
    ...     vehicle_contact=np.array([0, 1, 1, 0], bool),
    ...     waypoints_reached=2,
    ...     waypoints_total=4,
    ... )
    >>> out = episode_outcome(ep)
    >>> out.collided_vehicle, out.n_vehicle_collisions, out.km, out.waypoint_completion
    (True, 1, 0.03, 0.5)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import NDArray

from selfplaydrive.eval.stats import (
    KmBetween,
    MeanEstimate,
    Proportion,
    RateEstimate,
    km_between_incidents,
    mean_estimate,
    proportion,
    rate_per_km,
)
from selfplaydrive.eval.waymax_metrics import MAX_ACCEL, MAX_CURVATURE, kinematic_infeasibility

__all__ = [
    "COMFORT_LIMIT",
    "EVENT_BITS",
    "AgentEpisode",
    "EpisodeOutcome",
    "aggregate",
    "aggregate_to_dict",
    "count_onsets",
    "episode_outcome",
]

# Event bits of the simulator's per-step event byte (selfplaydrive/_sim/common.pxd EV_*).
EVENT_BITS = {
    "vehicle": 1,
    "pedestrian": 2,
    "road_edge": 4,
    "red_light": 8,
    "waypoint": 16,
    "comfort": 32,
}
COMFORT_LIMIT = 3.0  # [m/s²] longitudinal or lateral, the paper's comfort penalty (section 2.3)
_FLAG_FIELDS = ("vehicle_contact", "pedestrian_contact", "road_edge_contact", "red_light", "comfort_flags")


@dataclass(frozen=True)
class AgentEpisode:
    """What one agent did in one episode, as per-step arrays (T steps).

    Attributes:
        xy: (T, 2) positions [m], world frame.
        valid: (T,) bool, the agent exists at the step (default all True).
        vehicle_contact: (T,) bool, the box overlaps a vehicle (agent, parked car, obstacle).
        pedestrian_contact: (T,) bool, the box overlaps a pedestrian.
        road_edge_contact: (T,) bool, the box touches a road edge.
        red_light: (T,) bool, the box touches (or crossed) a red traffic-light line.
        comfort_flags: (T,) bool comfort-limit exceedances, used only when `a_long`/`a_lat`
            are absent (the simulator's EV_COMFORT bit).
        a_long: (T,) longitudinal acceleration [m/s²] or None.
        a_lat: (T,) lateral acceleration [m/s²] or None.
        vel: (T, 2) velocity [m/s] or None; with `yaw` it enables kinematic infeasibility.
        yaw: (T,) heading [rad] or None.
        waypoints_reached: Waypoints reached in the episode.
        waypoints_total: Waypoints assigned (0 = none; completion is then undefined).
        route_length_m: Length of the assigned route [m] (NaN = no route).
        route_progress_m: Distance advanced along that route [m].
        distance_m: Distance driven [m]; None = path length of `xy` over valid steps.
        dt: Step length [s].
        comfort_limit: Comfort bound on |a_long| and |a_lat| [m/s²].
        episode_id: Free-form label carried into the outcome.
    """

    xy: NDArray[np.float64]
    valid: NDArray[np.bool_] | None = None
    vehicle_contact: NDArray[np.bool_] | None = None
    pedestrian_contact: NDArray[np.bool_] | None = None
    road_edge_contact: NDArray[np.bool_] | None = None
    red_light: NDArray[np.bool_] | None = None
    comfort_flags: NDArray[np.bool_] | None = None
    a_long: NDArray[np.float64] | None = None
    a_lat: NDArray[np.float64] | None = None
    vel: NDArray[np.float64] | None = None
    yaw: NDArray[np.float64] | None = None
    waypoints_reached: int = 0
    waypoints_total: int = 0
    route_length_m: float = math.nan
    route_progress_m: float = math.nan
    distance_m: float | None = None
    dt: float = 0.1
    comfort_limit: float = COMFORT_LIMIT
    episode_id: str = ""

    def __post_init__(self) -> None:
        xy = np.asarray(self.xy, dtype=np.float64)
        if xy.ndim != 2 or xy.shape[1] != 2:
            raise ValueError(f"AgentEpisode {self.episode_id!r}: xy has shape {xy.shape}, expected (T, 2)")
        T = len(xy)
        object.__setattr__(self, "xy", xy)
        self._set_bool("valid", T, default=True)
        for name in _FLAG_FIELDS:
            self._set_bool(name, T, default=None if name == "comfort_flags" else False)
        for name, shape in (("a_long", (T,)), ("a_lat", (T,)), ("vel", (T, 2)), ("yaw", (T,))):
            self._set_float(name, shape)
        self._check_scalars()

    def _set_bool(self, name: str, T: int, default: bool | None) -> None:
        value = getattr(self, name)
        if value is None:
            arr = None if default is None else np.full(T, default, dtype=bool)
        else:
            arr = np.asarray(value).astype(bool)
            if arr.shape != (T,):
                raise ValueError(
                    f"AgentEpisode {self.episode_id!r}: {name} has shape {arr.shape}, expected ({T},)"
                )
        object.__setattr__(self, name, arr)

    def _set_float(self, name: str, shape: tuple[int, ...]) -> None:
        value = getattr(self, name)
        if value is None:
            return
        arr = np.asarray(value, dtype=np.float64)
        if arr.shape != shape:
            raise ValueError(
                f"AgentEpisode {self.episode_id!r}: {name} has shape {arr.shape}, expected {shape}"
            )
        object.__setattr__(self, name, arr)

    def _check_scalars(self) -> None:
        eid = self.episode_id
        if not 0 <= self.waypoints_reached <= max(self.waypoints_total, 0) or self.waypoints_total < 0:
            raise ValueError(
                f"AgentEpisode {eid!r}: waypoints_reached={self.waypoints_reached}, "
                f"waypoints_total={self.waypoints_total}; expected 0 ≤ reached ≤ total"
            )
        if self.distance_m is not None and not (math.isfinite(self.distance_m) and self.distance_m >= 0):
            raise ValueError(
                f"AgentEpisode {eid!r}: distance_m={self.distance_m!r}, expected a finite value ≥ 0 [m]"
            )
        if not self.dt > 0:
            raise ValueError(f"AgentEpisode {eid!r}: dt={self.dt!r}, expected a positive step length [s]")
        if (self.a_long is None) != (self.a_lat is None):
            raise ValueError(f"AgentEpisode {eid!r}: give both a_long and a_lat or neither")
        if (self.vel is None) != (self.yaw is None):
            raise ValueError(f"AgentEpisode {eid!r}: give both vel and yaw or neither")

    @classmethod
    def from_event_bits(cls, events: NDArray, xy: NDArray, **kwargs: object) -> AgentEpisode:
        """Build from the simulator's per-step event bytes (`EVENT_BITS`).

        Args:
            events: (T,) integer event bits of one agent, one byte per step.
            xy: (T, 2) positions [m].
            **kwargs: Any other `AgentEpisode` field.

        Returns:
            An `AgentEpisode` whose contact, red-light and comfort flags come from the bits.
        """
        ev = np.asarray(events)
        if not np.issubdtype(ev.dtype, np.integer) or ev.ndim != 1:
            raise ValueError(f"events has dtype {ev.dtype} and shape {ev.shape}: expected (T,) integer bits")
        flags = {
            "vehicle_contact": ev & EVENT_BITS["vehicle"],
            "pedestrian_contact": ev & EVENT_BITS["pedestrian"],
            "road_edge_contact": ev & EVENT_BITS["road_edge"],
            "red_light": ev & EVENT_BITS["red_light"],
            "comfort_flags": ev & EVENT_BITS["comfort"],
        }
        return cls(xy=xy, **flags, **kwargs)


@dataclass(frozen=True)
class EpisodeOutcome:
    """Per agent-episode outcomes (booleans are "at least once in the episode").

    Attributes:
        collided_vehicle: Any vehicle contact.
        collided_pedestrian: Any pedestrian contact.
        road_edge: Any road-edge contact.
        red_light: Any red-light violation.
        comfort_violation: Any step over the comfort limit (None = no acceleration data).
        comfort_step_fraction: Share of valid steps over the limit (NaN = no data).
        kinematically_infeasible: Any Waymax-infeasible transition (None = no vel/yaw).
        kin_infeasible_fraction: Share of valid transitions that are infeasible (NaN = none).
        waypoint_completion: reached / total (NaN when total = 0).
        all_waypoints: reached == total (None when total = 0).
        route_progress: route_progress_m / route_length_m, not clipped (NaN = no route).
        km: Distance driven [km].
        n_vehicle_collisions: Vehicle-contact onsets (edge-triggered incidents).
        n_pedestrian_collisions: Pedestrian-contact onsets.
        n_road_edge: Road-edge-contact onsets.
        n_red_light: Red-light onsets.
        waypoints_reached: Waypoints reached.
        episode_id: Label from the input.
    """

    collided_vehicle: bool
    collided_pedestrian: bool
    road_edge: bool
    red_light: bool
    comfort_violation: bool | None
    comfort_step_fraction: float
    kinematically_infeasible: bool | None
    kin_infeasible_fraction: float
    waypoint_completion: float
    all_waypoints: bool | None
    route_progress: float
    km: float
    n_vehicle_collisions: int
    n_pedestrian_collisions: int
    n_road_edge: int
    n_red_light: int
    waypoints_reached: int
    episode_id: str = ""

    def to_dict(self) -> dict[str, object]:
        """Plain dict (NaN floats kept; use stats' to_dict for JSON-safe aggregates)."""
        return asdict(self)


def count_onsets(flags: NDArray, valid: NDArray | None = None) -> int:
    """Count rising edges of a per-step contact flag (a persistent contact counts once).

    Invalid steps break a contact, so re-appearing in contact counts again (section 2.4).
    """
    f = np.asarray(flags, dtype=bool)
    if valid is not None:
        f = f & np.asarray(valid, dtype=bool)
    if f.size == 0:
        return 0
    return int(f[0]) + int(np.count_nonzero(f[1:] & ~f[:-1]))


def _km(ep: AgentEpisode) -> float:
    if ep.distance_m is not None:
        return ep.distance_m / 1000.0
    steps = np.linalg.norm(np.diff(ep.xy, axis=0), axis=1)
    return float(steps[ep.valid[1:] & ep.valid[:-1]].sum()) / 1000.0


def _comfort(ep: AgentEpisode) -> tuple[bool | None, float]:
    if ep.a_long is not None and ep.a_lat is not None:
        over = (np.abs(ep.a_long) > ep.comfort_limit) | (np.abs(ep.a_lat) > ep.comfort_limit)
    elif ep.comfort_flags is not None:
        over = ep.comfort_flags
    else:
        return None, math.nan
    over = over[ep.valid]
    if over.size == 0:
        return None, math.nan
    return bool(over.any()), float(over.mean())


def _kinematics(ep: AgentEpisode) -> tuple[bool | None, float]:
    if ep.vel is None or ep.yaw is None:
        return None, math.nan
    bad, ok = kinematic_infeasibility(ep.vel, ep.yaw, ep.valid, ep.dt, MAX_ACCEL, MAX_CURVATURE)
    if not ok.any():
        return None, math.nan
    return bool(bad[ok].any()), float(bad[ok].mean())


def episode_outcome(ep: AgentEpisode) -> EpisodeOutcome:
    """Reduce one `AgentEpisode` to its outcomes (see `EpisodeOutcome`)."""
    v = ep.valid
    comfort, comfort_frac = _comfort(ep)
    kin, kin_frac = _kinematics(ep)
    total = ep.waypoints_total
    has_route = math.isfinite(ep.route_length_m) and ep.route_length_m > 0
    return EpisodeOutcome(
        collided_vehicle=bool((ep.vehicle_contact & v).any()),
        collided_pedestrian=bool((ep.pedestrian_contact & v).any()),
        road_edge=bool((ep.road_edge_contact & v).any()),
        red_light=bool((ep.red_light & v).any()),
        comfort_violation=comfort,
        comfort_step_fraction=comfort_frac,
        kinematically_infeasible=kin,
        kin_infeasible_fraction=kin_frac,
        waypoint_completion=ep.waypoints_reached / total if total > 0 else math.nan,
        all_waypoints=(ep.waypoints_reached == total) if total > 0 else None,
        route_progress=ep.route_progress_m / ep.route_length_m if has_route else math.nan,
        km=_km(ep),
        n_vehicle_collisions=count_onsets(ep.vehicle_contact, v),
        n_pedestrian_collisions=count_onsets(ep.pedestrian_contact, v),
        n_road_edge=count_onsets(ep.road_edge_contact, v),
        n_red_light=count_onsets(ep.red_light, v),
        waypoints_reached=ep.waypoints_reached,
        episode_id=ep.episode_id,
    )


def _share(outcomes: Sequence[EpisodeOutcome], name: str) -> Proportion:
    """Wilson proportion of outcomes with `name` True among those where it is not None."""
    vals = [getattr(o, name) for o in outcomes]
    known = [x for x in vals if x is not None]
    return proportion(sum(bool(x) for x in known), len(known))


Estimate = Proportion | RateEstimate | KmBetween | MeanEstimate | float | int


def aggregate(items: Sequence[AgentEpisode | EpisodeOutcome]) -> dict[str, Estimate]:
    """Aggregate agent-episodes into rates with denominators and 95 % intervals.

    Proportions (Wilson, denominator = agent-episodes where defined): ``collided_vehicle``,
    ``collided_pedestrian``, ``collided_any``, ``road_edge``, ``red_light``, ``incident_any``
    (collision or road edge), ``comfort_violation``, ``kinematically_infeasible``,
    ``all_waypoints``. Rates per km (Garwood, pooled counts / pooled km): ``*_per_km``.
    Km between incidents (inverted Garwood): ``km_between_incidents`` (vehicle + pedestrian
    collisions + road-edge contacts, Gigaflow's incident), ``km_between_incidents_incl_red``
    and one per type. Means (Student-t): ``waypoint_completion``, ``route_progress``.

    Args:
        items: `AgentEpisode`s or already reduced `EpisodeOutcome`s.

    Returns:
        Dict of estimates plus ``n_agent_episodes`` (int) and ``km`` (float, total [km]).
    """
    outs = [o if isinstance(o, EpisodeOutcome) else episode_outcome(o) for o in items]
    km = float(sum(o.km for o in outs))
    res: dict[str, Estimate] = {"n_agent_episodes": len(outs), "km": km}
    for name in ("collided_vehicle", "collided_pedestrian", "road_edge", "red_light"):
        res[name] = _share(outs, name)
    collided = sum(o.collided_vehicle or o.collided_pedestrian for o in outs)
    res["collided_any"] = proportion(collided, len(outs))
    res["incident_any"] = proportion(
        sum(o.collided_vehicle or o.collided_pedestrian or o.road_edge for o in outs), len(outs)
    )
    for name in ("comfort_violation", "kinematically_infeasible", "all_waypoints"):
        res[name] = _share(outs, name)
    counts = {
        "vehicle_collisions": sum(o.n_vehicle_collisions for o in outs),
        "pedestrian_collisions": sum(o.n_pedestrian_collisions for o in outs),
        "road_edge": sum(o.n_road_edge for o in outs),
        "red_light": sum(o.n_red_light for o in outs),
        "waypoints": sum(o.waypoints_reached for o in outs),
    }
    for name, k in counts.items():
        res[f"{name}_per_km"] = rate_per_km(k, km)
    incidents = counts["vehicle_collisions"] + counts["pedestrian_collisions"] + counts["road_edge"]
    res["incidents_per_km"] = rate_per_km(incidents, km)
    res["km_between_incidents"] = km_between_incidents(incidents, km)
    res["km_between_incidents_incl_red"] = km_between_incidents(incidents + counts["red_light"], km)
    for name in ("vehicle_collisions", "pedestrian_collisions", "road_edge", "red_light"):
        res[f"km_between_{name}"] = km_between_incidents(counts[name], km)
    res["waypoint_completion"] = mean_estimate(np.array([o.waypoint_completion for o in outs], dtype=float))
    res["route_progress"] = mean_estimate(np.array([o.route_progress for o in outs], dtype=float))
    return res


def aggregate_to_dict(agg: dict[str, Estimate]) -> dict[str, object]:
    """JSON-safe version of an `aggregate` result (estimates via their `to_dict`)."""
    return {k: (v.to_dict() if hasattr(v, "to_dict") else v) for k, v in agg.items()}
