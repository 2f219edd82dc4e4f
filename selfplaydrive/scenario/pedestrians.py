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
        cw, other = crosswalks.cells.query_box(box), crossings.cells.query_box(box)
        n_cw, n_other = len(cw), len(other)
        if n_cw + n_other == 0:
            return out
        # one draw per pedestrian: pool, site, sideways shift, direction, kerb side, approach,
        # speed, start time, size
        u = rng.random((want, 9))
        share = self.crosswalk_share if n_other else 1.0
        use_cw = (u[:, 0] < share) if n_cw else np.zeros(want, dtype=bool)
        site = np.where(use_cw, u[:, 1] * n_cw, n_cw + u[:, 1] * n_other).astype(np.int64)
        pick = np.minimum(site, np.where(use_cw, n_cw, n_cw + n_other) - 1)  # u * n may round up to n
        start = np.concatenate([crosswalks.start[cw], crossings.start[other]])[pick]
        end = np.concatenate([crosswalks.end[cw], crossings.end[other]])[pick]
        half = np.concatenate([crosswalks.half_width[cw], crossings.half_width[other]])[pick]
        path = self._paths(start, end, half, u[:, 2:6])
        clear_r = vehicle_radius + self.vehicle_clearance
        ok = _clear_of(path[:, 0], vehicle_xy, clear_r)
        if stationary is not None and np.any(stationary):
            ok &= _path_clear_of(path, vehicle_xy[stationary], clear_r[stationary])
        n = int(ok.sum())
        u = u[ok]
        out.valid[:n] = True
        out.path[:n] = path[ok]
        out.num_points[:n] = PATH_POINTS
        out.speed[:n] = self.speed[0] + (self.speed[1] - self.speed[0]) * u[:, 6]
        out.start_time[:n] = self.start_time[0] + (self.start_time[1] - self.start_time[0]) * u[:, 7]
        out.size[:n] = (self.size[0] + (self.size[1] - self.size[0]) * u[:, 8])[:, None]
        return out

    def _paths(self, start: np.ndarray, end: np.ndarray, half: np.ndarray, u: np.ndarray) -> np.ndarray:
        """(n, 3, 2) approach point, extended crossing start, extended crossing end.

        u: (n, 4) uniforms for the sideways shift inside a crosswalk, the walking direction, the
        kerb side of the approach and its length.
        """
        d = end - start
        d = d / np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)[:, None]
        side = np.stack([-d[:, 1], d[:, 0]], axis=1)
        shift = (half * (2.0 * u[:, 0] - 1.0))[:, None] * side
        flip = (u[:, 1] < 0.5)[:, None]
        a = np.where(flip, end, start) + shift
        b = np.where(flip, start, end) + shift
        d = np.where(flip, -d, d)
        a = a - d * self.sidewalk_margin
        b = b + d * self.sidewalk_margin
        sign = np.where(u[:, 2] < 0.5, -1.0, 1.0)
        approach = a + side * (sign * self.max_approach * u[:, 3])[:, None]
        return np.stack([approach, a, b], axis=1)


def _clear_of(points: np.ndarray, xy: np.ndarray, radius: np.ndarray) -> np.ndarray:
    if len(xy) == 0 or len(points) == 0:
        return np.ones(len(points), dtype=bool)
    d = np.hypot(points[:, None, 0] - xy[None, :, 0], points[:, None, 1] - xy[None, :, 1])
    return np.all(d >= radius[None, :], axis=1)


def _path_clear_of(path: np.ndarray, xy: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """(n,) bool: no segment of each (n, T, 2) path passes within `radius` (V,) of `xy` (V, 2)."""
    a = path[:, :-1, None, :]  # (n, T-1, 1, 2)
    d = path[:, 1:, None, :] - a
    w = xy[None, None, :, :] - a  # (n, T-1, V, 2)
    t = np.clip(np.sum(w * d, axis=-1) / np.maximum(np.sum(d * d, axis=-1), 1e-12), 0.0, 1.0)
    gap = w - t[..., None] * d
    dist2 = np.sum(gap * gap, axis=-1)
    return np.all(dist2 >= (radius**2)[None, None, :], axis=(1, 2))


def _empty(slots: int) -> PedestrianBatch:
    return PedestrianBatch(
        valid=np.zeros(slots, dtype=bool),
        path=np.zeros((slots, PATH_POINTS, 2), dtype=np.float32),
        num_points=np.zeros(slots, dtype=np.int32),
        speed=np.zeros(slots, dtype=np.float32),
        start_time=np.zeros(slots, dtype=np.float32),
        size=np.zeros((slots, 2), dtype=np.float32),
    )
