"""Shared bookkeeping of the town generator: junction arms, per-direction lanes, the element sink.

An *arm* is one road seen from one of its end nodes, oriented outwards. Right-hand traffic:
looking outwards along an arm, the lanes coming in (towards the node) lie on the arm's
counter-clockwise (left) side, the lanes going out on its clockwise (right) side.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np

from selfplaydrive.maps.elements import LaneElement, MapElements
from selfplaydrive.maps.procedural.geometry import Path

LEFT, STRAIGHT, RIGHT = "left", "straight", "right"


@dataclass
class Arm:
    """One road at one junction, oriented away from the junction centre.

    Attributes:
        node: Junction node index.
        road: Road index.
        out_dir: Road direction (0: u -> v, 1: v -> u) of the lanes leaving the junction here.
        angle: Outward heading at the junction [rad].
        path: Outward reference line, starting at the node centre.
        lanes: Lanes per direction on this road.
        lane_width: [m].
        main: Whether the road is a main road.
        moves: Turn kind (LEFT, STRAIGHT, RIGHT) -> index of the target arm in the junction.
        left_pocket, right_pocket: Turn pockets on the incoming approach.
        crosswalk: Whether a crosswalk crosses this arm.
        hw_ccw, hw_cw: Half widths [m] from the reference line to the road edge at the
            junction, on the incoming (ccw) and outgoing (cw) side.
        r_core: Distance from the node centre along the arm where the road edges end and
            the junction's corner curbs begin [m].
        r_core_min: Smallest r_core the curbs allow (tightest corner rounding) [m].
        r_lane: Distance where the road lanes end / begin (stop line) [m].
    """

    node: int
    road: int
    out_dir: int
    angle: float
    path: Path
    lanes: int
    lane_width: float
    main: bool
    moves: dict[str, int] = field(default_factory=dict)
    left_pocket: bool = False
    right_pocket: bool = False
    crosswalk: bool = False
    hw_ccw: float = 0.0
    hw_cw: float = 0.0
    r_core: float = 0.0
    r_core_min: float = 0.0
    r_lane: float = 0.0

    @property
    def in_dir(self) -> int:
        """Road direction of the lanes arriving at the junction on this arm."""
        return 1 - self.out_dir

    @property
    def num_in_lanes(self) -> int:
        """Lanes at the stop line: through lanes plus pockets."""
        return self.lanes + int(self.left_pocket) + int(self.right_pocket)


@dataclass
class Junction:
    """A node with its arms sorted counter-clockwise by outward heading.

    Attributes:
        node: Node index.
        center: (2,) [m].
        arms: Arms, counter-clockwise.
        kind: "bend" (2 arms, no regulation), "signal", "priority", "uncontrolled" (right-hand
            rule) or "roundabout".
        priority: Arm indices on the priority road ("priority" kind); the others yield.
        phases: Signal phase (0 or 1) per arm ("signal" kind).
    """

    node: int
    center: np.ndarray
    arms: list[Arm]
    kind: str = "uncontrolled"
    priority: set[int] = field(default_factory=set)
    phases: list[int] = field(default_factory=list)

    def gap_after(self, k: int) -> float:
        """Counter-clockwise angle from arm k to the next arm [rad], in (0, 2 pi]."""
        a = self.arms[k].angle
        b = self.arms[(k + 1) % len(self.arms)].angle
        g = (b - a) % (2.0 * math.pi)
        return g if g > 1e-9 else 2.0 * math.pi


@dataclass
class DirLanes:
    """Lanes of one road direction: first segment (leaving a junction) and last (arriving).

    Lists run left to right in the direction of travel; `last_roles` holds "L" (left pocket),
    "T" (through lane) or "R" (right pocket) for each lane of the last segment.
    """

    first: list[int] = field(default_factory=list)
    last: list[int] = field(default_factory=list)
    last_roles: list[str] = field(default_factory=list)


class TownSink:
    """Collects the generated `MapElements` and hands out lane indices."""

    def __init__(self, name: str, source: str) -> None:
        self.elements = MapElements(name=name, source=source, crs="procedural town, local metres")

    def add_lane(
        self, centerline: np.ndarray, width: float, speed: float, source_id: str, in_junction: bool = False
    ) -> int:
        """Append a vehicle lane; returns its index."""
        self.elements.lanes.append(
            LaneElement(
                centerline=np.ascontiguousarray(centerline, dtype=np.float64),
                width=float(width),
                speed_limit=float(speed),
                source_id=source_id,
                in_junction=in_junction,
            )
        )
        return len(self.elements.lanes) - 1

    def link(self, a: int, b: int) -> None:
        """Make lane b a legal successor of lane a."""
        succ = self.elements.lanes[a].successors
        if b not in succ:
            succ.append(b)

    def neighbours(self, row: list[int], legal: bool) -> None:
        """Lanes `row` run side by side left to right; set left/right and change legality."""
        lanes = self.elements.lanes
        for a, b in itertools.pairwise(row):
            lanes[a].right, lanes[a].right_change_legal = b, legal
            lanes[b].left, lanes[b].left_change_legal = a, legal
