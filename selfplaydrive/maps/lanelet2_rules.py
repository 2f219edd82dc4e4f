"""Lanelet2 tagging rules: who may use a lanelet, one-way, speed limits, lane-change legality.

The rules follow the Lanelet2 tagging specification and its generic traffic rules
(`lanelet2_traffic_rules/GenericTrafficRules.cpp`), seen from a car (participant "vehicle"),
plus the two extra lane kinds the simulator knows (bus and bicycle lanes).
"""

from __future__ import annotations

import re
from enum import IntEnum

from selfplaydrive.maps.elements import LaneKind

# lanelet subtypes usable by vehicles (Lanelet2: road, highway, play_street, exit; "" defaults
# to vehicle). emergency_lane is for emergency vehicles only and is left out.
VEHICLE_SUBTYPES = frozenset({"", "road", "highway", "play_street", "exit"})
BUS_SUBTYPES = frozenset({"bus_lane"})
BICYCLE_SUBTYPES = frozenset({"bicycle_lane"})
CROSSWALK_SUBTYPES = frozenset({"crosswalk"})

TRUE_VALUES = frozenset({"yes", "true", "1"})
FALSE_VALUES = frozenset({"no", "false", "0"})

_SPEED = re.compile(r"^\s*([0-9]+(?:\.[0-9]*)?)\s*(km/h|kmh|kph|mph|m/s|mps)?\s*$")
_UNIT_TO_MPS = {
    None: 1 / 3.6,
    "km/h": 1 / 3.6,
    "kmh": 1 / 3.6,
    "kph": 1 / 3.6,
    "mph": 0.44704,
    "m/s": 1.0,
    "mps": 1.0,
}
# a traffic-sign code that carries its speed, e.g. "de274-60", "de274_60", "ee323-50" (>= 2 digits, so
# "de274_1", the sign variant number in the Lanelet2 example, is not read as 1 km/h)
_SIGN_SPEED = re.compile(r"^[a-z]{2}\d{3}[-_.](\d{2,3})$")
MIN_SPEED = 1.0  # [m/s] limits below this are treated as unreadable


class LaneChange(IntEnum):
    """Which way a line may be crossed, relative to the line's own point order."""

    NONE = 0
    TO_LEFT = 1
    TO_RIGHT = 2
    BOTH = 3


def parse_bool(value: str | None) -> bool | None:
    """Lanelet2 boolean tag value -> bool, or None when absent or unreadable."""
    if value in TRUE_VALUES:
        return True
    if value in FALSE_VALUES:
        return False
    return None


def parse_speed(value: str | None) -> float | None:
    """Speed tag -> [m/s]. Plain numbers are km/h (Lanelet2 convention); units km/h, mph, m/s.

    Returns None when absent, unreadable or implausibly small.
    """
    if not value:
        return None
    m = _SPEED.match(value)
    if not m:
        return None
    mps = float(m.group(1)) * _UNIT_TO_MPS[m.group(2)]
    return mps if mps >= MIN_SPEED else None


def sign_speed(subtype: str) -> float | None:
    """Speed [m/s] encoded in a traffic-sign subtype such as "de274-60", else None."""
    m = _SIGN_SPEED.match(subtype)
    return float(m.group(1)) / 3.6 if m else None


def lane_kind(tags: dict[str, str]) -> LaneKind | None:
    """Kind of directed lane a lanelet becomes, or None when no simulated agent may use it.

    `participant:*` tags override the subtype (Lanelet2 rule); otherwise the subtype decides:
    vehicle subtypes -> VEHICLE, bus_lane -> BUS, bicycle_lane -> BICYCLE. Crosswalks, walkways,
    rails, stairs, emergency lanes and unknown subtypes give None.
    """
    subtype = tags.get("subtype", "")
    if subtype in CROSSWALK_SUBTYPES:
        return None
    overrides = {k: v for k, v in tags.items() if k.startswith("participant:")}
    if overrides:
        if parse_bool(overrides.get("participant:vehicle")) or parse_bool(
            overrides.get("participant:vehicle:car")
        ):
            return LaneKind.VEHICLE
        if parse_bool(overrides.get("participant:vehicle:bus")):
            return LaneKind.BUS
        if parse_bool(overrides.get("participant:bicycle")):
            return LaneKind.BICYCLE
        return None
    if subtype in VEHICLE_SUBTYPES:
        return LaneKind.VEHICLE
    if subtype in BUS_SUBTYPES:
        return LaneKind.BUS
    if subtype in BICYCLE_SUBTYPES:
        return LaneKind.BICYCLE
    return None


def is_bidirectional(tags: dict[str, str], kind: LaneKind) -> bool:
    """Whether the lanelet may also be driven against its bounds' direction.

    Lanelet2: one_way decides; else a one_way:<participant> override; else one-way for every
    participant but pedestrians.
    """
    one_way = parse_bool(tags.get("one_way"))
    if one_way is not None:
        return not one_way
    key = {
        LaneKind.VEHICLE: "one_way:vehicle",
        LaneKind.BUS: "one_way:vehicle:bus",
        LaneKind.BICYCLE: "one_way:bicycle",
    }[kind]
    override = parse_bool(tags.get(key))
    return override is False


def line_lane_change(tags: dict[str, str]) -> LaneChange:
    """Lane changes a line string allows, relative to its stored direction (Lanelet2 rules).

    Explicit `lane_change`, `lane_change:left`, `lane_change:right` tags win; otherwise thin or
    thick lines allow: dashed -> both ways, dashed_solid -> to the right, solid_dashed -> to the
    left (the dashed half is on the side one crosses from), anything else -> none.
    """
    both = parse_bool(tags.get("lane_change"))
    if both is not None:
        return LaneChange.BOTH if both else LaneChange.NONE
    left = parse_bool(tags.get("lane_change:left"))
    right = parse_bool(tags.get("lane_change:right"))
    if left is not None:
        if not left:
            return LaneChange.NONE
        return LaneChange.BOTH if right else LaneChange.TO_LEFT
    if right is not None:
        return LaneChange.TO_RIGHT if right else LaneChange.NONE
    if tags.get("type") not in ("line_thin", "line_thick"):
        return LaneChange.NONE
    return {
        "dashed": LaneChange.BOTH,
        "dashed_solid": LaneChange.TO_RIGHT,
        "solid_dashed": LaneChange.TO_LEFT,
    }.get(tags.get("subtype", ""), LaneChange.NONE)


def can_cross(change: LaneChange, reversed_line: bool, to_left: bool) -> bool:
    """Whether a lane may cross a line towards its left (`to_left`) or right.

    Args:
        change: `line_lane_change` of the line in its stored direction.
        reversed_line: The lane runs against the line's stored direction (left/right swap).
        to_left: Crossing towards the lane's left.
    """
    if change == LaneChange.BOTH:
        return True
    if change == LaneChange.NONE:
        return False
    towards_line_left = to_left != reversed_line
    return change == (LaneChange.TO_LEFT if towards_line_left else LaneChange.TO_RIGHT)
