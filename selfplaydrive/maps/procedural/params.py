"""Parameters of the procedural town generator (docs/maps/procedural.md).

Every field has a unit and a default; `TownParams.validate` raises `ConfigError` naming the
field, the value and the allowed range, so a bad Hydra override fails before any geometry is
built.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

from selfplaydrive.errors import ConfigError

KMH = 1.0 / 3.6  # [m/s] per [km/h]


@dataclass(frozen=True)
class TownParams:
    """How a procedural town looks.

    The town is a jittered grid of streets (right-hand traffic). Main roads run along every
    `main_road_every`-th grid line, are straight, have `lanes_per_direction` lanes and get turn
    pockets; the other (minor, residential) streets have `minor_lanes_per_direction` lanes.

    Attributes:
        size: Edge length of the square town [m] (node grid spans [0, size] before jitter).
        block_size: Target distance between neighbouring grid nodes [m]; the actual spacing
            is `size / round(size / block_size)`.
        irregularity: 0 = a perfect grid; 1 = nodes moved by up to `0.15 * spacing`, most
            minor streets bent sideways by up to `0.06 * length`, more streets removed.
        removed_street_share: Share of the removable minor street segments taken out at
            irregularity 1 (scaled linearly with irregularity, plus a floor of a third of it),
            creating T intersections and larger blocks [-].
        lanes_per_direction: Lanes per direction on main roads (1-3).
        minor_lanes_per_direction: Lanes per direction on minor streets (1-3).
        main_road_every: A main road every this many grid lines (>= 2) [-].
        signalised_share: Share of the 3- and 4-way intersections (not roundabouts) that get
            traffic lights; main x main crossings are chosen first [-].
        priority_share: Share of the remaining all-minor intersections with a priority road
            (yield lines on the side road); the rest follow the right-hand rule, unsigned [-].
            (Main x minor junctions always give the main road priority; where a minor street
            crosses a main road, the side road gets STOP lines: regulation.stop_kind.)
        num_roundabouts: Roundabouts wanted; placed on nodes whose arms all have one lane per
            direction, never next to each other. Fewer are built (with a `UserWarning`) if the
            town has too few such nodes.
        crosswalk_density: Probability that an arm of an intersection or roundabout gets a
            crosswalk across it, just outside the junction [-].
        left_turn_lane_share: Probability that a main-road approach with a left turn and a
            straight move gets a dedicated left-turn pocket [-].
        right_turn_lane_share: Same for a right-turn pocket [-].
        turn_lane_length: Length of a turn pocket, from the start of its taper to the stop
            line [m] (shortened on short streets, dropped below 25 m).
        solid_line_length: Length before a stop line where lane changes are illegal (solid
            lines) [m].
        taper_length: Length over which a turn pocket widens from zero to full width [m].
        lane_width: Lane width on main roads and turn pockets [m].
        minor_lane_width: Lane width on minor streets [m].
        roundabout_lane_width: Width of the (single-lane) roundabout ring [m].
        roundabout_radius: Radius of the ring lane's centerline [m].
        shoulder: Distance from the outermost lane border to the road edge [m].
        corner_radius: Curb corner rounding at intersections [m].
        crosswalk_width: Width of a crosswalk in the direction of travel [m].
        main_speed_limit: [m/s] (50 km/h).
        minor_speed_limit: Residential streets [m/s] (40 km/h).
        zone30_share: Share of minor streets with `zone30_speed_limit` instead [-].
        zone30_speed_limit: [m/s] (30 km/h).
        roundabout_speed_limit: Ring, entries and exits [m/s] (30 km/h).
        sample_step: Spacing of centerline points on curved geometry [m].
    """

    size: float = 1600.0
    block_size: float = 90.0
    irregularity: float = 0.5
    removed_street_share: float = 0.15
    lanes_per_direction: int = 2
    minor_lanes_per_direction: int = 1
    main_road_every: int = 4
    signalised_share: float = 0.2
    priority_share: float = 0.5
    num_roundabouts: int = 4
    crosswalk_density: float = 0.4
    left_turn_lane_share: float = 0.8
    right_turn_lane_share: float = 0.3
    turn_lane_length: float = 45.0
    solid_line_length: float = 15.0
    taper_length: float = 15.0
    lane_width: float = 3.5
    minor_lane_width: float = 3.25
    roundabout_lane_width: float = 4.5
    roundabout_radius: float = 16.0
    shoulder: float = 0.5
    corner_radius: float = 6.0
    crosswalk_width: float = 4.0
    main_speed_limit: float = 50.0 * KMH
    minor_speed_limit: float = 40.0 * KMH
    zone30_share: float = 0.5
    zone30_speed_limit: float = 30.0 * KMH
    roundabout_speed_limit: float = 30.0 * KMH
    sample_step: float = 4.0

    def __post_init__(self) -> None:
        # config systems hand over 2.0 for 2: store whole numbers of the count fields as int
        for name in _INT_FIELDS:
            value = getattr(self, name)
            if isinstance(value, float) and value.is_integer():
                object.__setattr__(self, name, int(value))

    def validate(self) -> TownParams:
        """Check every field; return self.

        Raises:
            ConfigError: Naming the field, its value and the allowed range.
        """
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ConfigError(f"TownParams.{f.name} must be a finite number, got {value!r}")
        for name, lo, hi in _RANGES:
            value = getattr(self, name)
            if not lo <= value <= hi:
                raise ConfigError(f"TownParams.{name}={value!r} is outside the allowed range [{lo}, {hi}]")
        for name in _INT_FIELDS:
            if not isinstance(getattr(self, name), int):
                raise ConfigError(f"TownParams.{name} must be an integer, got {getattr(self, name)!r}")
        if self.size < 2 * self.block_size:
            raise ConfigError(
                f"TownParams.size={self.size} must be at least 2 * block_size={2 * self.block_size} "
                "(a town needs at least 2 x 2 blocks)"
            )
        if self.roundabout_radius - self.roundabout_lane_width / 2 - self.shoulder < 4.0:
            raise ConfigError(
                f"TownParams.roundabout_radius={self.roundabout_radius} leaves a central island under 4 m "
                f"radius with roundabout_lane_width={self.roundabout_lane_width}; use a radius >= "
                f"{4.0 + self.roundabout_lane_width / 2 + self.shoulder}"
            )
        return self


_INT_FIELDS = ("lanes_per_direction", "minor_lanes_per_direction", "main_road_every", "num_roundabouts")

# (field, min, max): ranges outside which the generator's geometry no longer holds together
_RANGES: tuple[tuple[str, float, float], ...] = (
    ("size", 200.0, 10000.0),  # a 10 km town takes about a minute
    ("block_size", 80.0, 400.0),
    ("irregularity", 0.0, 1.0),
    ("removed_street_share", 0.0, 0.6),
    ("lanes_per_direction", 1, 3),
    ("minor_lanes_per_direction", 1, 3),
    ("main_road_every", 2, 1000),
    ("signalised_share", 0.0, 1.0),
    ("priority_share", 0.0, 1.0),
    ("num_roundabouts", 0, 10000),
    ("crosswalk_density", 0.0, 1.0),
    ("left_turn_lane_share", 0.0, 1.0),
    ("right_turn_lane_share", 0.0, 1.0),
    ("turn_lane_length", 0.0, 150.0),
    ("solid_line_length", 0.0, 50.0),
    ("taper_length", 2.0, 50.0),
    ("lane_width", 2.5, 5.0),
    ("minor_lane_width", 2.5, 5.0),
    ("roundabout_lane_width", 3.0, 8.0),
    ("roundabout_radius", 8.0, 60.0),
    ("shoulder", 0.0, 3.0),
    ("corner_radius", 1.0, 20.0),
    ("crosswalk_width", 2.0, 8.0),
    ("main_speed_limit", 1.0, 40.0),
    ("minor_speed_limit", 1.0, 40.0),
    ("zone30_share", 0.0, 1.0),
    ("zone30_speed_limit", 1.0, 40.0),
    ("roundabout_speed_limit", 1.0, 40.0),
    ("sample_step", 0.5, 20.0),
)
