"""Rule-complete reward terms (issue #15): the failure modes of paper section 5.1 as optional
reward components, each off by default (the paper configuration and its digests are unchanged).

- ``red_intersection``: -1 on entering the area a red light controls by any path (own lane,
  oncoming lane, shoulder), not only on touching its line (the paper's reward hack, 5.1 "Red
  Lights"). The area is the red-light suite's (maps/rule_geometry.py).
- ``stop_sign``: -1 on crossing a STOP line without a stop before it (5.1 "Stop Signs"; YIELD
  lines stay unpenalised, as in the paper, section 2.1). One column of per-agent state.
- ``crosswalk_yield``: -1 on entering a crosswalk a pedestrian is on or about to step on
  (5.1: the policy yielded to 39 % of crossing pedestrians).
- ``wrong_way``: -1 per second (-dt per step) of driving against the direction of the lane the
  centre lies on (the oncoming-lane bypass, which the paper's lane association does not see).
- ``turn_lane``: -1 on driving through a junction lane the lane the agent entered the junction
  from does not lead to (paper 5.3 "Turning from the Correct Lane"; issue #16 item 3). One
  column of per-agent state: the entry lane on record.

Each is a `RuleTerm`, a map-bound term: ``bind(maps)`` packs the maps' tables into the args of
the `KernelTerm` the env steps (_sim/rules.pyx; layout in rewards/rule_tables.py). Select one
with ``LinearReward({..., "red_intersection": 1.0})`` or Hydra ``+reward.terms.red_intersection=1.0``;
its parameters with ``{weight: W, args: [...]}`` (`RuleTerm.param_names`). docs/rewards.md gives
the formulas; selfplaydrive/testing/rule_terms.py the NumPy references.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from selfplaydrive.errors import ConfigError
from selfplaydrive.maps.elements import LaneKind, StopKind
from selfplaydrive.maps.roadmap import RoadMap
from selfplaydrive.maps.rule_geometry import (
    GATE_DEPTH,
    GATE_LEFT,
    GATE_RIGHT,
    controlled_area,
    controlled_zones,
)
from selfplaydrive.obs.rule_features import CROSSWALK_HORIZON, CROSSWALK_MARGIN
from selfplaydrive.rewards.components import KernelTerm
from selfplaydrive.rewards.rule_tables import CELL, REACH, grid_body, pack

__all__ = [
    "RULE_TERMS",
    "TURN_PREDECESSORS",
    "RuleTerm",
    "crosswalk_records",
    "lane_records",
    "stop_records",
    "turn_records",
    "zone_records",
]

TURN_PREDECESSORS = 4
"""Most entry lanes a `turn_records` check record lists (the bundled town needs 1)."""
TURN_ENTRY, TURN_CHECK = 0.0, 1.0  # record kinds of `turn_records`


@dataclass(frozen=True)
class RuleTerm:
    """A map-bound rule term (`MapBoundTerm`): its kernel, parameters and map tables.

    Attributes:
        name: Column name.
        params: Parameter values, in the order of `param_names`.
        param_names: What each parameter is (with its unit).
        tables: RoadMap -> (records (n, R), boxes (n, 4), the map's number) of one map.
        state_dim: Per-agent state columns the kernel owns.
        doc: One line for listings.
        kernel: Name of the kernel in _sim/rules.pyx (default: `name`; a renamed copy keeps it).
        grid: (cell edge, reach) [m] of the per-map grids (rule_tables.py `grid_body`).
        table_params: How many of the last parameters shape the map tables: `tables` takes
            them after the map; the kernel skips them.
    """

    name: str
    params: tuple[float, ...]
    param_names: tuple[str, ...]
    tables: Callable[[RoadMap], tuple[np.ndarray, np.ndarray, float]]
    state_dim: int = 0
    doc: str = ""
    kernel: str = ""
    grid: tuple[float, float] = (CELL, REACH)
    table_params: int = 0

    def with_args(self, *args: float) -> RuleTerm:
        """This term with other parameter values (``{weight: W, args: [...]}`` in a reward).

        Raises:
            ConfigError: Another number of values than `param_names`, or a non-finite one.
        """
        if len(args) != len(self.param_names):
            raise ConfigError(
                f"reward term {self.name!r}: args must be {len(self.param_names)} numbers "
                f"({', '.join(self.param_names)}), got {list(args)!r}"
            )
        try:
            values = tuple(float(a) for a in args)
        except (TypeError, ValueError):
            values = (math.nan,)
        if not all(math.isfinite(v) for v in values):
            raise ConfigError(f"reward term {self.name!r}: args must be finite numbers, got {list(args)!r}")
        return replace(self, params=values)

    def bind(self, maps: Sequence[RoadMap]) -> KernelTerm:
        """The kernel term whose args pack `maps`' tables (world w reads ``maps[map_id[w]]``)."""
        from selfplaydrive._sim import rules

        extra = self.params[len(self.params) - self.table_params :]
        bodies = []
        for m in maps:
            records, boxes, scalar = self.tables(m, *extra)
            bodies.append(grid_body(records, boxes, *self.grid, scalar=scalar))
        args = pack(self.name, self.params, bodies)
        address = int(rules.rule_term_addresses()[self.kernel or self.name])
        return KernelTerm(self.name, address, args, "builtin", self.doc, rules, self.state_dim)


# map tables -----------------------------------------------------------------------------------
def zone_records(road_map: RoadMap) -> tuple[np.ndarray, np.ndarray, float]:
    """Controlled areas: (cx, cy, ux, uy, group) per (light line, vehicle lane), and boxes."""
    z = controlled_zones(road_map)
    rec = np.stack([z[:, 0], z[:, 1], np.cos(z[:, 2]), np.sin(z[:, 2]), z[:, 3]], axis=1)
    corners = [controlled_area(r[:2], float(r[2])) for r in z]
    return rec, _boxes(corners), 0.0


def stop_records(road_map: RoadMap) -> tuple[np.ndarray, np.ndarray, float]:
    """STOP-line segments: (ax, ay, ex, ey, nx, ny) per segment of a STOP line and lane it
    applies to (e = b - a, n the unit normal pointing along the lane), and boxes. YIELD lines
    and lines that apply to no lane are left out."""
    rows, boxes = [], []
    offsets, index = road_map.stop_lane_offsets, road_map.stop_lane_index
    for k in range(len(road_map.stop_lines)):
        if int(road_map.stop_kind[k]) != int(StopKind.STOP):
            continue
        pts = road_map.stop_lines[k].astype(np.float64)
        for lane in index[offsets[k] : offsets[k + 1]]:
            u = _lane_direction(road_map, int(lane), pts)
            for a, b in itertools.pairwise(pts):
                e = b - a
                n = np.array([e[1], -e[0]]) / max(float(np.hypot(*e)), 1e-9)
                n = n if float(n @ u) >= 0.0 else -n
                rows.append([a[0], a[1], e[0], e[1], n[0], n[1]])
                boxes.append([min(a[0], b[0]), min(a[1], b[1]), max(a[0], b[0]), max(a[1], b[1])])
    return np.array(rows, np.float64).reshape(-1, 6), np.array(boxes, np.float64).reshape(-1, 4), 0.0


def crosswalk_records(road_map: RoadMap) -> tuple[np.ndarray, np.ndarray, float]:
    """Crosswalk polygons: (nv, xmin, ymin, xmax, ymax, x0, y0, ...) padded to the map's most
    vertices, and boxes."""
    polys = [road_map.crosswalks[k].astype(np.float64) for k in range(len(road_map.crosswalks))]
    vmax = max([len(p) for p in polys], default=0)
    rows = np.zeros((len(polys), 5 + 2 * vmax))
    for j, p in enumerate(polys):
        rows[j, :5] = [len(p), *p.min(axis=0), *p.max(axis=0)]
        rows[j, 5 : 5 + 2 * len(p)] = p.reshape(-1)
    return rows, rows[:, 1:5].copy(), 0.0


def lane_records(road_map: RoadMap) -> tuple[np.ndarray, np.ndarray, float]:
    """Vehicle-lane centerline segments: (ax, ay, ux, uy, length, half width), boxes grown by
    the half width, and the narrowest half width (the kernel's shortcut: a car its lane
    association places within it of a centerline going its way is on a lane going its way)."""
    lanes = road_map.lanes
    rows = []
    for i in range(len(lanes)):
        if int(lanes.kind[i]) == int(LaneKind.BICYCLE):
            continue
        start, u, ln = _pieces(lanes.centerlines[i].astype(np.float64))
        rows.append(np.column_stack([start, u, ln, np.full(len(ln), 0.5 * float(lanes.width[i]))]))
    rec = np.concatenate(rows) if rows else np.zeros((0, 6))
    b = rec[:, :2] + rec[:, 2:4] * rec[:, 4:5]
    lo = np.minimum(rec[:, :2], b) - rec[:, 5:6]
    hi = np.maximum(rec[:, :2], b) + rec[:, 5:6]
    return rec, np.concatenate([lo, hi], axis=1), float(rec[:, 5].min()) if len(rec) else 0.0


def turn_records(road_map: RoadMap, entry_back: float = 0.0) -> tuple[np.ndarray, np.ndarray, float]:
    """Gates of the turn_lane term: (ax, ay, ex, ey, ux, uy, kind, lane, n, p_0 .. p_{K-1})
    with K = `TURN_PREDECESSORS`, and boxes.

    Each gate is the segment a .. a + e across a lane, e perpendicular to the lane's unit
    direction u there, |e| = the lane's width (half a width either side of the centerline).
    Kind `TURN_ENTRY`: on a non-junction vehicle lane with a vehicle successor in a junction,
    `entry_back` m of arc length before its last point (at its first point if it is shorter;
    0: at its last point), n = 0. Kind `TURN_CHECK`: at half the arc length of a junction
    vehicle lane; p_0 .. p_{n-1} are its non-junction vehicle predecessors (the entry lanes it
    is legal from; the rest of the row is -1). Lane ids index the map's `lanes`.

    Args:
        road_map: The map.
        entry_back: [m] how far before the junction the entry lane is read (>= 0). With 10,
            a car must be in a lane that leads to its junction lane 10 m before the junction,
            not only when it crosses the junction's start (docs/rewards.md "turn_lane").

    Raises:
        ConfigError: A junction lane with more than `TURN_PREDECESSORS` such predecessors,
            or a negative `entry_back`.
    """
    if not entry_back >= 0.0:
        raise ConfigError(
            "reward term 'turn_lane': entry_back must be a distance >= 0 [m] before the junction, "
            f"got {entry_back!r}"
        )
    lanes = road_map.lanes
    vehicle = np.asarray(lanes.kind) != int(LaneKind.BICYCLE)
    junction = np.asarray(lanes.in_junction, bool) & vehicle
    rows = []
    for i in map(int, np.flatnonzero(vehicle)):
        if junction[i]:
            preds = [int(p) for p in lanes.predecessors(i) if vehicle[p] and not junction[p]]
            if len(preds) > TURN_PREDECESSORS:
                raise ConfigError(
                    f"reward term 'turn_lane': junction lane {i} of map {road_map.name!r} has "
                    f"{len(preds)} entry lanes; the tables hold at most "
                    f"TURN_PREDECESSORS = {TURN_PREDECESSORS}"
                )
            point, u = _point_at_half_length(lanes.centerlines[i].astype(np.float64))
            rows.append(_gate(point, u, float(lanes.width[i]), TURN_CHECK, i, preds))
        elif any(junction[s] for s in lanes.successors(i)):
            p = lanes.centerlines[i].astype(np.float64)
            point, u = (p[-1], _last_direction(p)) if entry_back == 0.0 else _point_before_end(p, entry_back)
            rows.append(_gate(point, u, float(lanes.width[i]), TURN_ENTRY, i, []))
    rec = np.array(rows, np.float64).reshape(-1, 9 + TURN_PREDECESSORS)
    b = rec[:, :2] + rec[:, 2:4]
    boxes = np.concatenate([np.minimum(rec[:, :2], b), np.maximum(rec[:, :2], b)], axis=1)
    return rec, boxes, 0.0


def _gate(
    point: np.ndarray, u: np.ndarray, width: float, kind: float, lane: int, preds: list[int]
) -> list[float]:
    """One `turn_records` row: the gate across the lane at `point`, its direction `u` there."""
    e = np.array([-u[1], u[0]]) * width  # left normal, a lane width long
    a = point - 0.5 * e
    pad = [-1.0] * (TURN_PREDECESSORS - len(preds))
    return [a[0], a[1], e[0], e[1], u[0], u[1], kind, lane, len(preds), *preds, *pad]


def _pieces(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The centerline's pieces of nonzero length: start points, unit directions, lengths."""
    d = np.diff(p, axis=0)
    ln = np.hypot(d[:, 0], d[:, 1])
    ok = ln > 1e-6
    return p[:-1][ok], d[ok] / ln[ok, None], ln[ok]


def _last_direction(p: np.ndarray) -> np.ndarray:
    return _pieces(p)[1][-1]


def _point_at_half_length(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The point at half the centerline's arc length and the unit direction of its piece."""
    start, u, ln = _pieces(p)
    ends = np.cumsum(ln)
    half = 0.5 * ends[-1]
    k = min(int(np.searchsorted(ends, half)), len(ln) - 1)
    return start[k] + u[k] * (half - (ends[k] - ln[k])), u[k]


def _point_before_end(p: np.ndarray, back: float) -> tuple[np.ndarray, np.ndarray]:
    """The point `back` m of arc length before the centerline's end (its first point if it is
    shorter) and the unit direction of its piece."""
    start, u, ln = _pieces(p)
    ends = np.cumsum(ln)
    s = max(float(ends[-1]) - back, 0.0)
    k = min(int(np.searchsorted(ends, s)), len(ln) - 1)
    return start[k] + u[k] * (s - (ends[k] - ln[k])), u[k]


def _lane_direction(road_map: RoadMap, lane: int, pts: np.ndarray) -> np.ndarray:
    """Unit direction of `lane`'s centerline segment nearest to the line points `pts`."""
    p = road_map.lanes.centerlines[lane].astype(np.float64)
    mid = 0.5 * (p[:-1] + p[1:])
    d = np.diff(p, axis=0)
    k = int(np.argmin(np.min(np.hypot(*(mid[:, None] - pts[None]).transpose(2, 0, 1)), axis=1)))
    return d[k] / max(float(np.hypot(*d[k])), 1e-9)


def _boxes(corners: list[np.ndarray]) -> np.ndarray:
    if not corners:
        return np.zeros((0, 4))
    c = np.stack(corners)
    return np.concatenate([c.min(axis=1), c.max(axis=1)], axis=1)


RULE_TERMS = (
    RuleTerm(
        "red_intersection",
        (GATE_LEFT, GATE_RIGHT, GATE_DEPTH, math.cos(math.radians(60.0))),
        ("gate_left [m]", "gate_right [m]", "gate_depth [m]", "cos of the largest heading deviation"),
        zone_records,
        doc="R = -1 on entering a red light's controlled area (any path) heading into it",
    ),
    RuleTerm(
        "stop_sign",
        (0.5, 8.0),
        ("v_stop [m/s]", "distance [m] (front of the car, before the line)"),
        stop_records,
        state_dim=1,
        doc="R = -1 on crossing a STOP line without a stop (v <= 0.5 m/s) within 8 m before it",
    ),
    RuleTerm(
        "crosswalk_yield",
        # the same "about to enter" rule as the observation's crosswalk state (obs=rules)
        (CROSSWALK_HORIZON, CROSSWALK_MARGIN),
        ("t_ahead [s]", "margin [m]"),
        crosswalk_records,
        doc="R = -1 on entering a crosswalk a pedestrian is on or reaches within 1.5 s",
    ),
    RuleTerm(
        "wrong_way",
        (1.0,),
        ("v_min [m/s]",),
        lane_records,
        doc="R = -dt (-1 per second) driving against the lane the centre lies on",
        grid=(5.0, 0.05),  # tests the current position only: finer cells, reach for rounding
    ),
    RuleTerm(
        "turn_lane",
        # entry_back 0: the lane is read where the car crosses the junction's start
        (math.cos(math.radians(45.0)), 0.0),
        (
            "cos of the largest heading deviation from the junction lane",
            "entry_back [m]: the entry lane is read this far before the junction",
        ),
        turn_records,
        state_dim=1,
        doc="R = -1 on driving through a junction lane the lane entered from does not lead to",
        grid=(5.0, REACH),
        table_params=1,
    ),
)
