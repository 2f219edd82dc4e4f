"""Where a policy touches road edges: every road-edge contact onset, classified by the road
around the car (docs/analyses.md, "Where road-edge contacts happen").

A road-edge contact is the rising edge of an acting agent's SD_EV_OFFROAD event bit (paper
section 2.3: the road-edge penalty and, with `terminate_threshold`, the end of the agent). Each
onset gets one category, first match wins:

- `dead_end`: the car is on a lane without successors, within `end_radius` of that lane's end.
  Real maps are cut at their border, so their border lanes end without a successor (the
  Lanelet2 loader closes the drivable area's outline across them), and a policy trained on a
  map without such lanes drives into the cut;
- `crossing`: the nearest road-edge segment makes more than `crossing_deg` with the car's
  heading (the car drives into an edge, not along it: a missed turn, a lane end elsewhere);
- `junction`: the car is on a junction lane (an edge along it: a corner cut too tight);
- `along`: an edge along an ordinary lane (lateral drift, a narrow lane).

"The car's lane" is the lane whose centerline segment is nearest to the car's centre among
those heading within 45 degrees of the car (none within `lane_radius`: no lane), and "the
nearest road-edge segment" is measured from the car's centre: proxies for the contact point,
good enough to tell a lane end from a curb. A contact that ends the last agent of a world is
not seen: the world restarts within that step, and the event bits with it.

Example:
    >>> from selfplaydrive.eval.edge_contacts import edge_contacts
    >>> table = edge_contacts(env, policy, steps=1500, seed=0)  # doctest: +SKIP
    >>> print(table.markdown())  # doctest: +SKIP
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from selfplaydrive.maps.roadmap import RoadMap, SegmentType

CATEGORIES = ("dead_end", "crossing", "junction", "along")
EV_OFFROAD = 4  # SD_EV_OFFROAD (include/selfplaydrive_abi.pxd)
LANE_HEADING_TOLERANCE = np.pi / 4  # [rad] a lane counts as the car's within this heading error


@dataclass(frozen=True)
class MapGeometry:
    """The segments the classification reads, from a compiled map (float64, local frame [m]).

    Attributes:
        edge_start, edge_dir: (E, 2) road-edge segment start points and unit directions.
        edge_len: (E,) their lengths.
        lane_start, lane_dir, lane_len: the same for lane-centre segments (S rows).
        lane_owner: (S,) lane index of each lane-centre segment.
        dead_end: (L,) bool, the lane has no successor.
        lane_end: (L, 2) last centerline point of each lane.
        in_junction: (L,) bool.
    """

    edge_start: np.ndarray
    edge_dir: np.ndarray
    edge_len: np.ndarray
    lane_start: np.ndarray
    lane_dir: np.ndarray
    lane_len: np.ndarray
    lane_owner: np.ndarray
    dead_end: np.ndarray
    lane_end: np.ndarray
    in_junction: np.ndarray

    @classmethod
    def of(cls, road_map: RoadMap) -> MapGeometry:
        seg, lanes = road_map.segments, road_map.lanes
        edge = seg.type == SegmentType.ROAD_EDGE
        lane = seg.type == SegmentType.LANE_CENTER
        ends = np.array([lanes.centerlines[i][-1] for i in range(len(lanes.width))], dtype=np.float64)
        return cls(
            edge_start=seg.start[edge].astype(np.float64),
            edge_dir=seg.dir[edge].astype(np.float64),
            edge_len=seg.length[edge].astype(np.float64),
            lane_start=seg.start[lane].astype(np.float64),
            lane_dir=seg.dir[lane].astype(np.float64),
            lane_len=seg.length[lane].astype(np.float64),
            lane_owner=seg.owner[lane].astype(np.int64),
            dead_end=np.diff(lanes.succ_offsets) == 0,
            lane_end=ends.reshape(-1, 2),
            in_junction=np.asarray(lanes.in_junction, dtype=bool),
        )


def _distances(p: np.ndarray, start: np.ndarray, direction: np.ndarray, length: np.ndarray) -> np.ndarray:
    """(K,) distance from point `p` (2,) to each segment start + t * direction, t in [0, length]."""
    t = np.clip(((p - start) * direction).sum(axis=1), 0.0, length)
    return np.linalg.norm(start + t[:, None] * direction - p, axis=1)


def car_lane(geom: MapGeometry, xy: np.ndarray, heading: float, lane_radius: float = 5.0) -> int:
    """The lane of a car at `xy` [m] heading `heading` [rad]: the owner of the nearest lane-centre
    segment among those heading within 45 degrees of the car, if within `lane_radius` [m]; -1
    otherwise (module docstring)."""
    if not len(geom.lane_len):
        return -1
    p = np.asarray(xy, dtype=np.float64)
    u = np.array([np.cos(heading), np.sin(heading)])
    aligned = geom.lane_dir @ u > np.cos(LANE_HEADING_TOLERANCE)
    d = np.where(aligned, _distances(p, geom.lane_start, geom.lane_dir, geom.lane_len), np.inf)
    k = int(np.argmin(d))
    return int(geom.lane_owner[k]) if d[k] <= lane_radius else -1


def classify_onset(
    geom: MapGeometry,
    xy: np.ndarray,
    heading: float,
    end_radius: float = 10.0,
    crossing_deg: float = 45.0,
    lane_radius: float = 5.0,
) -> str:
    """The category (`CATEGORIES`) of a road-edge contact by a car at `xy` [m] heading
    `heading` [rad] (module docstring)."""
    p = np.asarray(xy, dtype=np.float64)
    u = np.array([np.cos(heading), np.sin(heading)])
    lane = car_lane(geom, p, heading, lane_radius)
    if lane >= 0 and geom.dead_end[lane] and np.linalg.norm(geom.lane_end[lane] - p) <= end_radius:
        return "dead_end"
    if len(geom.edge_len):
        k = int(np.argmin(_distances(p, geom.edge_start, geom.edge_dir, geom.edge_len)))
        if abs(float(geom.edge_dir[k] @ u)) < np.cos(np.radians(crossing_deg)):
            return "crossing"
    if lane >= 0 and geom.in_junction[lane]:
        return "junction"
    return "along"


@dataclass
class EdgeContacts:
    """Road-edge contact onsets by category.

    Attributes:
        counts: Onsets per category (`CATEGORIES`).
        agent_steps: Agent-steps recorded (steps in which an agent acted).
        dt: Simulation step [s].
        onsets: One (category, map index, x, y, heading, speed) row per onset.
    """

    counts: dict[str, int] = field(default_factory=lambda: dict.fromkeys(CATEGORIES, 0))
    agent_steps: int = 0
    dt: float = 0.1
    onsets: list[tuple[str, int, float, float, float, float]] = field(default_factory=list)

    @property
    def total(self) -> int:
        return sum(self.counts.values())

    def per_hour(self, name: str | None = None) -> float:
        """Onsets (of category `name`; all when None) per hour of driving."""
        n = self.total if name is None else self.counts[name]
        hours = self.agent_steps * self.dt / 3600.0
        return n / hours if hours > 0 else float("nan")

    def to_dict(self) -> dict[str, Any]:
        total = max(self.total, 1)
        return {
            "onsets": self.total,
            "agent_steps": self.agent_steps,
            "per_hour": self.per_hour(),
            "categories": {
                k: {"onsets": v, "share": v / total, "per_hour": self.per_hour(k)}
                for k, v in self.counts.items()
            },
        }

    def markdown(self) -> str:
        total = max(self.total, 1)
        lines = ["| where | onsets | share | per hour of driving |", "|---|---|---|---|"]
        for k, v in self.counts.items():
            lines.append(f"| {k} | {v} | {100 * v / total:.1f} % | {self.per_hour(k):.1f} |")
        lines.append(f"| all | {self.total} | 100 % | {self.per_hour():.1f} |")
        return "\n".join(lines)


class EdgeContactRecorder:
    """Call `record()` after every `env.step`; `result` holds the classified onsets.

    Args:
        env: A `VecEnv`.
        end_radius: [m] `dead_end` when the car is this close to its dead-end lane's end.
        crossing_deg: [deg] `crossing` when the nearest edge is more oblique than this.
    """

    def __init__(self, env: Any, end_radius: float = 10.0, crossing_deg: float = 45.0) -> None:
        if not end_radius > 0 or not 0 < crossing_deg < 90:
            raise ValueError(
                f"end_radius={end_radius!r}, crossing_deg={crossing_deg!r}: expected end_radius > 0 "
                "and 0 < crossing_deg < 90"
            )
        self.env, self.end_radius, self.crossing_deg = env, float(end_radius), float(crossing_deg)
        self._geoms = [MapGeometry.of(m) for m in env.maps]
        self._prev = np.zeros(env.num_agents, dtype=np.uint8)
        self.result = EdgeContacts(dt=float(env.params.dt))

    def record(self) -> None:
        """Read the step just taken."""
        st, acted = self.env.state, self.env.reward_mask
        events = np.where(acted, st.events, 0).astype(np.uint8)
        onset = events & ~self._prev
        self._prev = events
        self.result.agent_steps += int(acted.sum())
        for i in np.flatnonzero(onset & EV_OFFROAD):
            m = int(st.map_id[i // self.env.agents_per_world])
            x, y, h = float(st.x[i]), float(st.y[i]), float(st.heading[i])
            name = classify_onset(self._geoms[m], np.array([x, y]), h, self.end_radius, self.crossing_deg)
            self.result.counts[name] += 1
            self.result.onsets.append((name, m, x, y, h, float(st.speed[i])))


def edge_contacts(
    env: Any,
    policy: Callable[[np.ndarray, Any], np.ndarray],
    steps: int,
    seed: int | None = None,
    **recorder_kwargs: float,
) -> EdgeContacts:
    """Drive `policy` in `env` for `steps` env steps from a reset and classify every road-edge
    contact onset (`EdgeContactRecorder`; worlds reset on their own as their episodes end).

    Args:
        env: A `VecEnv`.
        policy: Maps the env's observations (and the env) to actions.
        steps: Env steps (at least 1).
        seed: Reset seed (None: the env's own).
        **recorder_kwargs: `end_radius`, `crossing_deg`.
    """
    if int(steps) < 1:
        raise ValueError(f"steps: expected >= 1, got {steps!r}")
    env.reset(seed=seed)
    if hasattr(policy, "reset"):
        policy.reset()
    recorder = EdgeContactRecorder(env, **recorder_kwargs)
    for _ in range(int(steps)):
        env.step(policy(env.observations, env))
        recorder.record()
    return recorder.result
