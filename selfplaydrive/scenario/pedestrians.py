"""Pedestrians that cross the road on precomputed trajectories (paper section 2.2).

Each pedestrian gets a three-point polyline: it appears `approach` m (U(0, max_approach)) along
the kerb from the start of a crossing, walks to the crossing's start, then straight across to
the far side. Crossings are either crosswalk long axes (with a random sideways shift inside the
crosswalk) or edge-to-edge paths perpendicular to a lane away from crosswalks, both
precomputed in `MapIndex`; a pedestrian takes a crosswalk with probability `crosswalk_share`
(sites drawn uniformly with replacement within each kind), and each end is extended
`sidewalk_margin` m beyond the road so pedestrians start and finish off the road. The walking
direction is random. A pedestrian walks at U(0.8, 1.8) m/s after waiting U(0, 10) s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from selfplaydrive._sim.pedestrians import pedestrian_batch
from selfplaydrive.errors import ConfigError
from selfplaydrive.scenario.index import Crossings

PATH_POINTS = 3  # T: approach point, crossing start, crossing end


@dataclass
class PedestrianBatch:
    """Pedestrians of one world (P slots). Shapes follow `Scenario.ped_*`."""

    valid: np.ndarray
    path: np.ndarray
    num_points: np.ndarray
    speed: np.ndarray
    start_time: np.ndarray
    size: np.ndarray


class PedestrianSampler:
    """Samples crossing pedestrians inside a region.

    Args:
        count: (low, high) number of pedestrians per world, inclusive, capped by the slots.
        crosswalk_share: Probability a pedestrian uses a crosswalk when the region has one.
        speed: (low, high) walking speed [m/s].
        start_time: (low, high) waiting time before walking [s].
        size: (low, high) edge of the square pedestrian box [m].
        max_approach: Longest approach leg along the kerb before crossing [m].
        sidewalk_margin: How far beyond the road edge / crosswalk end a crossing starts [m].
        vehicle_clearance: Minimum distance [m] between a pedestrian's start point and any
            vehicle's box (checked against its bounding circle).

    Raises:
        ConfigError: On a malformed range or a probability outside [0, 1].
    """

    def __init__(
        self,
        count: tuple[int, int] = (0, 8),
        crosswalk_share: float = 0.5,
        speed: tuple[float, float] = (0.8, 1.8),
        start_time: tuple[float, float] = (0.0, 10.0),
        size: tuple[float, float] = (0.5, 0.8),
        max_approach: float = 5.0,
        sidewalk_margin: float = 1.0,
        vehicle_clearance: float = 1.0,
    ) -> None:
        lo, hi = (int(v) for v in count)
        if not 0 <= lo <= hi:
            raise ConfigError(f"PedestrianSampler.count must satisfy 0 <= low <= high, got {count}")
        if not 0.0 <= crosswalk_share <= 1.0:
            raise ConfigError(f"PedestrianSampler.crosswalk_share must lie in [0, 1], got {crosswalk_share}")
        for name, r in (("speed", speed), ("size", size)):
            if not 0 < float(r[0]) <= float(r[1]):
                raise ConfigError(f"PedestrianSampler.{name} must satisfy 0 < low <= high, got {r}")
        if not 0 <= float(start_time[0]) <= float(start_time[1]):
            raise ConfigError(f"PedestrianSampler.start_time must satisfy 0 <= low <= high, got {start_time}")
        self.count = (lo, hi)
        self.crosswalk_share = float(crosswalk_share)
        self.speed = (float(speed[0]), float(speed[1]))
        self.start_time = (float(start_time[0]), float(start_time[1]))
        self.size = (float(size[0]), float(size[1]))
        self.max_approach = float(max_approach)
        self.sidewalk_margin = float(sidewalk_margin)
        self.vehicle_clearance = float(vehicle_clearance)

    def sample(
        self,
        rng: np.random.Generator,
        crossings: Crossings,
        crosswalks: Crossings,
        box: np.ndarray,
        slots: int,
        vehicle_xy: np.ndarray,
        vehicle_radius: np.ndarray,
        stationary: np.ndarray | None = None,
    ) -> PedestrianBatch:
        """Pedestrians for one world.

        Args:
            rng: Seeded generator.
            crossings, crosswalks: Precomputed crossings of the map (`MapIndex`).
            box: (4,) region [m]; crossings are used when their midpoint lies inside.
            slots: P, pedestrian slots of the env.
            vehicle_xy: (V, 2) centres of all placed vehicles [m].
            vehicle_radius: (V,) their bounding-circle radii [m].
            stationary: (V,) bool, vehicles that stand still at the start (static vehicles,
                parked agents); a path passing within radius + `vehicle_clearance` of one is
                dropped, since the pedestrian would walk into it. Default: none.
        """
        out = _empty(slots)
        want = min(int(rng.integers(self.count[0], self.count[1] + 1)), slots)
        if want == 0:
            return out
        still = np.zeros(len(vehicle_xy), dtype=bool) if stationary is None else stationary
        # sites in the box, then (when there are any) one (want, 9) draw: pool, site, sideways
        # shift, direction, kerb side, approach, speed, start time, size; paths, clearance
        # tests and the kept pedestrians' slots in one kernel call
        pedestrian_batch(
            self, crosswalks.kernel, crossings.kernel, rng, np.ascontiguousarray(box, dtype=np.float64),
            want, np.ascontiguousarray(vehicle_xy, dtype=np.float64).reshape(-1, 2),
            np.ascontiguousarray(vehicle_radius, dtype=np.float64),
            np.ascontiguousarray(still, dtype=bool), out,
        )  # fmt: skip
        return out


def _empty(slots: int) -> PedestrianBatch:
    return PedestrianBatch(
        valid=np.zeros(slots, dtype=bool),
        path=np.zeros((slots, PATH_POINTS, 2), dtype=np.float32),
        num_points=np.zeros(slots, dtype=np.int32),
        speed=np.zeros(slots, dtype=np.float32),
        start_time=np.zeros(slots, dtype=np.float32),
        size=np.zeros((slots, 2), dtype=np.float32),
    )
