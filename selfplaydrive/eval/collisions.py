"""What the vehicle collisions are: each collision onset classified by partner and geometry.

`CollisionRecorder(env)` reads the env after every `step` and logs each vehicle-collision onset
(rising edge of the EV_COLLIDE bit of an agent that acted) with:

- its partner (`collision_partner`): the nearest body whose box overlaps the agent's box at the
  event step (separating-axis test): other agents of the world (active, kept as obstacles, or
  ended in this very step), then static vehicles; without an overlapping box (a contact the
  kernel found between sub-steps) the nearest body, flagged `overlap = False`. A collision
  between two agents is logged once (from the lower slot);
- its kind: `static` (a parked vehicle), else by the heading difference of the two agents
  `dh` in [0, pi]: `rear_end` (dh <= `crossing_rad`, 0.5 rad: both drive the same way),
  `head_on` (dh >= `head_on_rad`, 2.6 rad: they meet from opposite directions), `crossing`
  (between: junction conflicts and merges);
- the faster vehicle's speed after the step [m/s] (the collision penalty's `v`, section 2.3)
  and both cars' absolute lateral offsets `lane_s` from the associated lane centre [m] (NaN
  without a lane within 60 deg), which separate drift in a lane from conflicts on correct lines;
- `stopped`: one of the two agents stood (speed < 0.5 m/s), so the other drove into it; with a
  static partner, the agent itself stood (it crept into the parked vehicle);
- `junction`: either car is on a junction lane (its lane as `eval.edge_contacts.car_lane` finds
  it: the nearest lane centre heading within 45 deg, within 5 m), which tells conflicts inside
  junctions (turns across oncoming traffic, crossing paths) from those on ordinary roads.

`CollisionRecorder.breakdown()` sums the log into a `CollisionBreakdown` (counts, shares,
medians per kind; `to_dict()`, `markdown()`). `selfplaydrive eval`'s completion analysis
records one alongside its missed-waypoint table (docs/analyses.md section 5).

Limitation: an autoreset clears the event bits of a world's last step before Python sees them,
so a collision in the very last step of an episode is not logged (1 step in 200-400).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from selfplaydrive.eval.edge_contacts import MapGeometry, car_lane
from selfplaydrive.eval.metrics import EVENT_BITS
from selfplaydrive.eval.waymax_metrics import boxes_overlap

__all__ = ["KINDS", "CollisionBreakdown", "CollisionRecorder", "collision_partner", "geometry"]

KINDS = ("static", "rear_end", "crossing", "head_on")
EV_COLLIDE = EVENT_BITS["vehicle"]
STOPPED_SPEED = 0.5  # [m/s]
_CENTER_MAX_ALPHA = np.pi / 3  # lane offsets only where the centre term is given (section 2.3)


def collision_partner(env: Any, i: int) -> tuple[str, int, bool]:
    """Partner of agent slot `i`'s vehicle collision at the step just taken.

    Returns:
        ("agent", slot, overlap) or ("static", static index, overlap); ("none", -1, False) when
        the world holds no other body.
    """
    st, A = env.state, env.agents_per_world
    w = i // A
    a = np.arange(w * A, (w + 1) * A)
    present = st.agent_valid[a].astype(bool) & (
        st.active[a].astype(bool) | st.obstacle[a].astype(bool) | env.reward_mask[a]
    )
    a = a[present & (a != i)]
    S = len(st.st_valid) // env.num_worlds
    s = np.arange(w * S, (w + 1) * S)
    s = s[st.st_valid[s].astype(bool)]
    boxes = np.concatenate(
        [
            np.c_[st.x[a], st.y[a], st.length[a], st.width[a], st.heading[a]],
            np.c_[st.st_x[s], st.st_y[s], st.st_len[s], st.st_wid[s], np.arctan2(st.st_sin[s], st.st_cos[s])],
        ]
    ).astype(np.float64)
    if len(boxes) == 0:
        return "none", -1, False
    ego = np.array([[st.x[i], st.y[i], st.length[i], st.width[i], st.heading[i]]], dtype=np.float64)
    dist = np.hypot(boxes[:, 0] - ego[0, 0], boxes[:, 1] - ego[0, 1])
    hit = boxes_overlap(np.repeat(ego, len(boxes), axis=0), boxes)
    k = int(np.argmin(np.where(hit, dist, np.inf))) if hit.any() else int(np.argmin(dist))
    if k < len(a):
        return "agent", int(a[k]), bool(hit[k])
    return "static", int(s[k - len(a)]), bool(hit[k])


def geometry(heading_a: float, heading_b: float, crossing_rad: float = 0.5, head_on_rad: float = 2.6) -> str:
    """`rear_end`, `crossing` or `head_on` from two headings [rad] (module docstring)."""
    dh = abs((float(heading_a) - float(heading_b) + np.pi) % (2.0 * np.pi) - np.pi)
    if dh <= crossing_rad:
        return "rear_end"
    return "head_on" if dh >= head_on_rad else "crossing"


@dataclass
class CollisionBreakdown:
    """Logged collision onsets, one entry per collision (an agent pair counted once).

    Attributes:
        kind: (n,) str, one of `KINDS`.
        speed: (n,) the faster vehicle's speed after the step [m/s] (a static one's is 0).
        ego_offset, partner_offset: (n,) |lane_s| [m] of the logging agent and its partner
            (NaN: no lane within 60 deg, or a static partner).
        stopped: (n,) bool, one of the two agents stood (< 0.5 m/s); with a static partner,
            the agent itself.
        overlap: (n,) bool, the partner's box overlapped at the event step.
        junction: (n,) bool, either car was on a junction lane.
    """

    kind: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype="<U8"))
    speed: np.ndarray = field(default_factory=lambda: np.zeros(0))
    ego_offset: np.ndarray = field(default_factory=lambda: np.zeros(0))
    partner_offset: np.ndarray = field(default_factory=lambda: np.zeros(0))
    stopped: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    overlap: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    junction: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))

    def __post_init__(self) -> None:
        n = len(self.kind)
        for name in ("speed", "ego_offset", "partner_offset", "stopped", "overlap", "junction"):
            if len(getattr(self, name)) != n:
                raise ValueError(
                    f"CollisionBreakdown.{name}: expected {n} entries (as kind), "
                    f"got {len(getattr(self, name))}"
                )
        unknown = sorted(set(self.kind.tolist()) - set(KINDS))
        if unknown:
            raise ValueError(f"CollisionBreakdown.kind: unknown kinds {unknown}, expected any of {KINDS}")

    def to_dict(self) -> dict[str, Any]:
        """Per kind: count, share of all collisions, medians of speed and offsets, shares stopped
        and at a junction."""
        n = len(self.kind)
        out: dict[str, Any] = {"collisions": n}
        for k in KINDS:
            m = self.kind == k
            out[k] = {
                "count": int(m.sum()),
                "share": float(m.sum() / n) if n else float("nan"),
                "median_speed": _median(self.speed[m]),
                "median_ego_offset": _median(self.ego_offset[m]),
                "median_partner_offset": _median(self.partner_offset[m]),
                "share_stopped": float(self.stopped[m].mean()) if m.any() else float("nan"),
                "share_junction": float(self.junction[m].mean()) if m.any() else float("nan"),
            }
        return out

    def markdown(self) -> str:
        """The `to_dict` table as markdown."""
        d = self.to_dict()
        lines = [
            f"Vehicle collisions: {d['collisions']} (an agent pair counted once)",
            "",
            "| kind | count | share | median speed [m/s] | median abs lane offset, agent / partner [m] "
            "| one stood | at a junction |",
            "|---|---|---|---|---|---|---|",
        ]
        for k in KINDS:
            r = d[k]
            lines.append(
                f"| {k} | {r['count']} | {_fmt(100 * r['share'], 1)} % | {_fmt(r['median_speed'], 1)} | "
                f"{_fmt(r['median_ego_offset'], 2)} / {_fmt(r['median_partner_offset'], 2)} | "
                f"{_fmt(100 * r['share_stopped'], 0)} % | {_fmt(100 * r['share_junction'], 0)} % |"
            )
        return "\n".join(lines)


def _fmt(x: float, digits: int) -> str:
    return "-" if not np.isfinite(x) else f"{x:.{digits}f}"


def _median(x: np.ndarray) -> float:
    x = x[np.isfinite(x)]
    return float(np.median(x)) if len(x) else float("nan")


class CollisionRecorder:
    """Log the vehicle-collision onsets of a `VecEnv`; call `record()` after every `env.step`.

    Args:
        env: The `VecEnv` (read only: `state` views, `reward_mask`, `maps`).
        crossing_rad: Heading difference [rad] above which two agents cross (not rear-end).
        head_on_rad: Heading difference [rad] from which two agents meet head-on.
    """

    def __init__(self, env: Any, crossing_rad: float = 0.5, head_on_rad: float = 2.6) -> None:
        if not 0.0 < float(crossing_rad) < float(head_on_rad) <= np.pi:
            raise ValueError(
                f"crossing_rad={crossing_rad}, head_on_rad={head_on_rad}: "
                "expected 0 < crossing_rad < head_on_rad <= pi"
            )
        self.env = env
        self.crossing_rad, self.head_on_rad = float(crossing_rad), float(head_on_rad)
        self._prev = np.zeros(env.num_agents, dtype=np.uint8)
        self._geoms = [MapGeometry.of(m) for m in env.maps]
        self._rows: list[tuple[str, float, float, float, bool, bool, bool]] = []

    def record(self) -> None:
        """Read the step just taken."""
        st, acted = self.env.state, self.env.reward_mask
        ev = np.where(acted, st.events, 0).astype(np.uint8)
        onset = ev & ~self._prev
        self._prev = ev
        for i in np.flatnonzero(onset & EV_COLLIDE):
            self._log(int(i), onset)

    def _offset(self, i: int) -> float:
        st = self.env.state
        ok = st.lane_valid[i] and abs(float(st.lane_alpha[i])) < _CENTER_MAX_ALPHA
        return abs(float(st.lane_s[i])) if ok else float("nan")

    def _on_junction(self, *slots: int) -> bool:
        st = self.env.state
        geom = self._geoms[int(st.map_id[slots[0] // self.env.agents_per_world])]
        for i in slots:
            lane = car_lane(geom, np.array([st.x[i], st.y[i]]), float(st.heading[i]))
            if lane >= 0 and geom.in_junction[lane]:
                return True
        return False

    def _log(self, i: int, onset: np.ndarray) -> None:
        st = self.env.state
        what, j, overlap = collision_partner(self.env, i)
        if what == "none":
            return
        v = float(st.speed[i])
        if what == "static":
            self._rows.append(
                ("static", v, self._offset(i), float("nan"), v < STOPPED_SPEED, overlap, self._on_junction(i))
            )
            return
        if j < i and onset[j] & EV_COLLIDE:
            return  # the pair was logged from the lower slot
        vj = float(st.speed[j])
        kind = geometry(st.heading[i], st.heading[j], self.crossing_rad, self.head_on_rad)
        self._rows.append(
            (
                kind,
                max(v, vj),
                self._offset(i),
                self._offset(j),
                min(v, vj) < STOPPED_SPEED,
                overlap,
                self._on_junction(i, j),
            )
        )

    def breakdown(self) -> CollisionBreakdown:
        """Everything logged so far."""
        if not self._rows:
            return CollisionBreakdown()
        kind, speed, ego, partner, stopped, overlap, junction = zip(*self._rows, strict=True)
        return CollisionBreakdown(
            kind=np.array(kind),
            speed=np.array(speed, dtype=np.float64),
            ego_offset=np.array(ego, dtype=np.float64),
            partner_offset=np.array(partner, dtype=np.float64),
            stopped=np.array(stopped, dtype=bool),
            overlap=np.array(overlap, dtype=bool),
            junction=np.array(junction, dtype=bool),
        )
