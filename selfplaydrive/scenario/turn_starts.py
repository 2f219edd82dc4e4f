"""Turn-lane starts: a training curriculum for turning from the correct lane (paper section 5.3).

Routes of `PaperSpawner` come with waypoints every few seconds along the lanes they follow, so
when a route changes lanes before a turn, a waypoint on the new lane usually tells the agent
which lane to take, and it changes late, when that waypoint appears. The paper's turn-lane
suite gives only waypoints after the junction: the agent must infer the lane from where the
route goes. `TurnLaneStarts` puts some agents of a normal world into exactly that situation:
an agent slot is moved onto a lane from which its coming turn is not legal, 30-100 m before
the junction, with its waypoints 10 m and 30 m after the turn (`scenario.turn_sites`, the
suite's own site search and start rules), among the world's other traffic.

The bundled town's suite sites are the ones trained on here (other draws of start points and
speeds); the Tartu suite tells whether the skill carries to a map that was not.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import numpy as np

from selfplaydrive.maps.lane_paths import LaneGeometry
from selfplaydrive.maps.roadmap import RoadMap
from selfplaydrive.scenario.turn_sites import TurnSites
from selfplaydrive.scenario.types import Scenario

# tries per placed agent: random starts inside the region checked against the other bodies
TRIES_PER_AGENT = 16
# per-agent fields of `Scenario` that a move or a removal writes (the first three are not zeroed)
AGENT_FIELDS = ("agent_valid", "agent_parked", "agent_lane", "agent_xy", "agent_heading", "agent_speed",
                "agent_length", "agent_width", "waypoints", "num_waypoints", "coeffs", "hidden")  # fmt: skip
# a start keeps this far inside the region's edge [m], so its junction is usually inside too
REGION_MARGIN = 20.0


@dataclass
class StartTable:
    """Every admissible turn-lane start of one map, one row per start point.

    Attributes:
        xy: (n, 2) float64 [m] start point on the wrong lane's centerline.
        heading: (n,) float64 [rad].
        lane: (n,) int64 the wrong lane W the agent starts on.
        speed_cap: (n,) float64 [m/s] 0.8 x W's speed limit (the suite's cap).
        waypoints: (n, 2, 2) float64 [m] the two exit waypoints of the row's site.
    """

    xy: np.ndarray
    heading: np.ndarray
    lane: np.ndarray
    speed_cap: np.ndarray
    waypoints: np.ndarray


def start_table(road_map: RoadMap, finder: TurnSites | None = None) -> StartTable:
    """All starts of all turn-lane sites on `road_map` (`TurnSites.site_starts`).

    Args:
        road_map: The map.
        finder: The site search and start rules (default: the paper suite's).
    """
    suite = finder or TurnSites()
    geo = LaneGeometry(road_map)
    xy, hd, lane, cap, wp = [], [], [], [], []
    for j, p, w in suite.sites(geo):
        st = suite.site_starts(geo, j, p, w)
        if st is None:
            continue
        n = len(st.xy)
        xy.append(st.xy)
        hd.append(st.heading)
        lane.append(np.full(n, w, np.int64))
        cap.append(np.full(n, 0.8 * float(road_map.lanes.speed_limit[w])))
        wp.append(np.broadcast_to(st.exit_waypoints, (n, 2, 2)))
    if not xy:
        z = np.zeros
        return StartTable(z((0, 2)), z(0), z(0, np.int64), z(0), z((0, 2, 2)))
    cat = np.concatenate
    return StartTable(cat(xy), cat(hd), cat(lane), cat(cap), cat(wp).astype(np.float64))


class TurnLaneStarts:
    """Moves up to `count` driving agents of a sampled world to turn-lane starts (`apply`).

    A moved agent keeps its slot, size, reward coefficients and hidden parameters; it gets a
    start row of `start_table` inside the world's region, a speed U(`speed`) capped by 0.8 x
    the lane's limit, and the row's two exit waypoints as its whole route. A start is taken
    only when its centre keeps `min_agent_distance` from every other agent and its bounding
    circle `static_gap` from every static vehicle's, so scenarios stay valid; fewer agents are
    moved when no start fits (no warning: the world is still a normal one).

    Args:
        speed: (low, high) initial speed [m/s] (the suite's U(5, 8)).
        min_agent_distance: Minimum distance between agent centres [m].
        static_gap: Clearance between bounding circles of a moved agent and static vehicles [m].
    """

    def __init__(
        self,
        speed: tuple[float, float] = (5.0, 8.0),
        min_agent_distance: float = 15.0,
        static_gap: float = 1.0,
    ) -> None:
        self.speed = (float(speed[0]), float(speed[1]))
        self.min_agent_distance = float(min_agent_distance)
        self.static_gap = float(static_gap)
        self._last: tuple[weakref.ref, StartTable] | None = None

    def table(self, road_map: RoadMap) -> StartTable:
        """The map's `start_table`, built once per map (the last map is cached)."""
        last = self._last
        if last is not None and last[0]() is road_map:
            return last[1]
        table = start_table(road_map)
        self._last = (weakref.ref(road_map), table)
        return table

    def apply(
        self, sc: Scenario, road_map: RoadMap, rng: np.random.Generator, count: int, clear: bool = False
    ) -> int:
        """Move up to `count` agents of `sc` in place; returns how many were moved.

        Draws, in order: a permutation of the driving agents' slots, then per placed agent up
        to `TRIES_PER_AGENT` start rows and one speed (all from `rng`).

        Args:
            clear: Make the world a turn-lane world: every agent (parked ones too) is a
                candidate, agents are placed one after another keeping their distance from
                the ones placed before, and the agents that find no start are removed (their
                slots made invalid), so the world holds turn-lane starts only.
        """
        table = self.table(road_map)
        lo = sc.region[:2].astype(np.float64) + REGION_MARGIN
        hi = sc.region[2:].astype(np.float64) - REGION_MARGIN
        inside = np.flatnonzero(np.all((table.xy > lo) & (table.xy < hi), axis=1))
        slots = np.flatnonzero(sc.agent_valid if clear else sc.agent_valid & ~sc.agent_parked)
        if count <= 0 or len(inside) == 0 or len(slots) == 0:
            return 0
        slots = slots[rng.permutation(len(slots))]
        static_xy = sc.static_xy[sc.static_valid].astype(np.float64)
        static_r = 0.5 * np.hypot(sc.static_length[sc.static_valid], sc.static_width[sc.static_valid])
        saved = {name: getattr(sc, name).copy() for name in AGENT_FIELDS} if clear else None
        if clear:
            sc.agent_valid[slots] = False  # placed back one by one
        moved = 0
        for slot in slots[:count]:
            row = self._fit(sc, int(slot), table, inside, static_xy, static_r, rng)
            if row < 0:
                continue
            self._move(sc, int(slot), table, row, rng)
            moved += 1
        if saved is not None:
            if moved == 0:  # not one start fits: the world stays a normal one
                for name, value in saved.items():
                    getattr(sc, name)[...] = value
            else:
                _blank_agents(sc, np.flatnonzero(~sc.agent_valid))
        return moved

    def _fit(self, sc, slot, table, inside, static_xy, static_r, rng) -> int:
        """A start row whose agent clears every other body, or -1."""
        others = sc.agent_valid.copy()
        others[slot] = False
        agent_xy = sc.agent_xy[others].astype(np.float64)
        radius = 0.5 * float(np.hypot(sc.agent_length[slot], sc.agent_width[slot]))
        for row in inside[rng.integers(0, len(inside), TRIES_PER_AGENT)]:
            p = table.xy[row]
            if len(agent_xy) and np.min(np.hypot(*(agent_xy - p).T)) < self.min_agent_distance:
                continue
            if len(static_xy) and np.any(np.hypot(*(static_xy - p).T) < static_r + radius + self.static_gap):
                continue
            return int(row)
        return -1

    def _move(self, sc: Scenario, slot: int, table: StartTable, row: int, rng: np.random.Generator) -> None:
        """Put agent `slot` at start `row`: pose, lane, speed and the two exit waypoints."""
        sc.agent_xy[slot] = table.xy[row]
        sc.agent_heading[slot] = table.heading[row]
        sc.agent_speed[slot] = min(rng.uniform(*self.speed), table.speed_cap[row])
        sc.agent_lane[slot] = table.lane[row]
        sc.agent_parked[slot] = False
        sc.agent_valid[slot] = True
        sc.waypoints[slot, :2] = table.waypoints[row]
        sc.waypoints[slot, 2:] = table.waypoints[row, 1]
        sc.num_waypoints[slot] = 2


def _blank_agents(sc: Scenario, slots: np.ndarray) -> None:
    """Reset agent `slots` to the padding of `Scenario.empty` (invalid, zeros, lane -1)."""
    for name in AGENT_FIELDS[3:]:
        getattr(sc, name)[slots] = 0
    sc.agent_parked[slots] = False
    sc.agent_lane[slots] = -1
