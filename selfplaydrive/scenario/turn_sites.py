"""Turn-lane sites: where a car must change lanes before a turn (paper section 5.3).

Shared by the turn-lane suite (`eval/suites/turn_lanes.py`, which draws one start per site) and
the turn-lane training starts (`scenario/turn_starts.py`, which draws from all of them). From the
lane graph only, so it works on procedural and Lanelet2 maps:

1. A *turn* is a junction lane J whose heading changes by at least `min_turn` (left or right).
   Its *correct lanes* are the non-junction lanes from which J is reached by lane following
   alone (backward search from J's predecessors, up to `search_back` m).
2. A *wrong lane* W is a neighbour (left/right, up to three hops) of a correct lane that is not
   itself correct, yet reaches a correct lane by following lanes and legal lane changes toward
   the turn side only (a left turn needs changes to the left). Each (J, W) pair is a site.
3. A start lies on W's centerline, `start_distance` m before J's start measured along the
   correct corridor, at least 0.75 lane widths beside it, leaving at least `change_room` m of
   W ahead when the change must happen on W itself; its waypoints lie 10 m and 30 m along the
   exit lane.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from selfplaydrive.maps.lane_paths import LaneGeometry, cumlen, point_at, project


@dataclass
class SiteStarts:
    """The admissible starts of one turn-lane site (`TurnLaneSuite.site_starts`).

    Attributes:
        xy: (n, 2) float64 start points on the wrong lane's centerline [m].
        heading: (n,) float64 lane heading there [rad].
        d_entry: (n,) float64 distance to the junction's start along the correct corridor [m].
        corridor: (m, 2) correct approach corridor ending with the junction lane [m].
        s_entry: Arc length of the junction's start along `corridor` [m].
        exit_path: (q, 2) exit lanes after the junction [m].
        exit_waypoints: (2, 2) the waypoints 10 m and 30 m along `exit_path` [m].
    """

    xy: np.ndarray
    heading: np.ndarray
    d_entry: np.ndarray
    corridor: np.ndarray
    s_entry: float
    exit_path: np.ndarray
    exit_waypoints: np.ndarray


class TurnSites:
    """Site search and admissible starts of the turn-lane situation (see the module docstring).

    Args:
        min_turn: Heading change [rad] that makes a junction lane a turn.
        start_distance: (low, high) distance [m] of a start before the junction.
        change_room: Lane length [m] left ahead of the start when the change is due on it.
        search_back: How far back [m] correct lanes are searched.
    """

    def __init__(
        self,
        min_turn: float = 0.7,
        start_distance: tuple[float, float] = (30.0, 100.0),
        change_room: float = 12.0,
        search_back: float = 250.0,
    ) -> None:
        if not 0.0 < start_distance[0] <= start_distance[1]:
            raise ValueError(f"start_distance: expected 0 < low <= high [m], got {start_distance}")
        self.min_turn = float(min_turn)
        self.start_distance = (float(start_distance[0]), float(start_distance[1]))
        self.change_room = float(change_room)
        self.search_back = float(search_back)

    def sites(self, geo: LaneGeometry) -> list[tuple[int, int, int]]:
        """All (junction lane J, its approach lane P, wrong start lane W) triples of the map of
        `geo` (`LaneGeometry(road_map)`, shared with `site_starts`)."""
        L = geo.lanes
        out = []
        for j in np.flatnonzero(L.in_junction & geo.vehicle):
            turn = geo.turn(j)
            if abs(turn) < self.min_turn or not any(geo.vehicle[q] for q in L.successors(j)):
                continue
            for p in L.predecessors(j):
                if L.in_junction[p] or not geo.vehicle[p]:
                    continue
                up = _upstream(geo, int(p), self.search_back)
                for w in _neighbours(geo, up):
                    if _reaches_by_changes(geo, w, up, left=turn > 0):
                        out.append((int(j), int(p), w))
        return out

    def site_starts(self, geo: LaneGeometry, j: int, p: int, w: int) -> SiteStarts | None:
        """Every admissible start of site (j, p, w) on a 1 m grid along W, or None when the
        site has no exit room or no start fits (the generator draws one of them; the training
        starts of `scenario.turn_starts` draw from all sites)."""
        L = geo.lanes
        nonj = lambda i: not L.in_junction[i]  # noqa: E731
        back = geo.chain_back(p, self.search_back, allow=nonj)
        exit_chain = geo.chain_forward(geo.straightest_succ(j), 60.0)
        corridor = geo.path([*back, j])
        s_entry = cumlen(corridor)[-1] - geo.length[j]
        exit_path = geo.path(exit_chain)
        if cumlen(exit_path)[-1] < 15.0:
            return None
        first_change = _first_move_is_change(geo, w, set(_upstream(geo, p, self.search_back)), j)
        room = self.change_room if first_change else 0.0
        s = np.arange(0.0, max(geo.length[w] - room, 0.0) + 1e-9, 1.0)
        xy, hd = point_at(geo.line(w), s)
        sp, lat, _ = project(corridor, xy)
        d_entry = s_entry - sp
        # clearly in another lane: not at a split where both lanes still share the centerline
        ok = (sp > 0.5) & (np.abs(lat) >= 0.75 * L.width[p]) & (np.abs(lat) < 3.0 * L.width[p] + 1.0)
        ok &= (d_entry >= self.start_distance[0]) & (d_entry <= self.start_distance[1])
        if not ok.any():
            return None
        exit_wp, _ = point_at(exit_path, np.array([10.0, min(30.0, cumlen(exit_path)[-1])]))
        k = np.flatnonzero(ok)
        return SiteStarts(xy[k], hd[k], d_entry[k], corridor, float(s_entry), exit_path, exit_wp)


def _upstream(geo: LaneGeometry, p: int, limit: float) -> list[int]:
    """Non-junction lanes from which lane p is reached by following lanes (p included)."""
    L = geo.lanes
    seen, queue, out = {p: 0.0}, deque([p]), [p]
    while queue:
        x = queue.popleft()
        for q in L.predecessors(x):
            q = int(q)
            d = seen[x] + geo.length[q]
            if q in seen or L.in_junction[q] or not geo.vehicle[q] or d > limit:
                continue
            seen[q] = d
            out.append(q)
            queue.append(q)
    return out


def _neighbours(geo: LaneGeometry, lanes: list[int]) -> list[int]:
    """Lanes up to three left/right hops from `lanes`, not among them, outside junctions."""
    L, base = geo.lanes, set(lanes)
    found: set[int] = set()
    for x in lanes:
        for side in (L.left, L.right):
            y = x
            for _ in range(3):
                y = int(side[y])
                if y < 0:
                    break
                if y not in base and not L.in_junction[y] and geo.vehicle[y]:
                    found.add(y)
    return sorted(found)


def _moves(geo: LaneGeometry, x: int, left: bool) -> list[tuple[int, bool]]:
    """(next lane, is a lane change) moves from x: following outside junctions, legal changes
    toward the turn side."""
    L = geo.lanes
    out = [(int(q), False) for q in L.successors(x) if not L.in_junction[q] and geo.vehicle[q]]
    nb, legal = (L.left[x], L.left_legal[x]) if left else (L.right[x], L.right_legal[x])
    if nb >= 0 and legal and geo.vehicle[nb]:
        out.append((int(nb), True))
    return out


def _reaches_by_changes(geo: LaneGeometry, w: int, up: list[int], left: bool, depth: int = 12) -> bool:
    """Whether lane w reaches a lane of `up` with lane changes toward the turn side."""
    target, seen, queue = set(up), {w}, deque([(w, 0)])
    while queue:
        x, d = queue.popleft()
        for y, _ in _moves(geo, x, left):
            if y in target:
                return True
            if y not in seen and d < depth:
                seen.add(y)
                queue.append((y, d + 1))
    return False


def _first_move_is_change(geo: LaneGeometry, w: int, up: set[int], j: int) -> bool:
    """True when no following successor of w leads toward `up` (the change must happen on w)."""
    left = geo.turn(j) > 0
    follow = [y for y, change in _moves(geo, w, left) if not change]
    return not any(_reaches_by_changes(geo, y, list(up), left) or y in up for y in follow)
