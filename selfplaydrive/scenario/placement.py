"""Placement helpers of the spawner (paper section 2.2): candidate poses and spacing rules.

Candidates are drawn uniformly over lane length inside the region (chunk chosen with
probability proportional to its length, then a uniform arc length inside it). Separation is a
greedy pass over a random candidate order: a candidate is accepted when it keeps the required
distance to everything accepted before it. The pass is bounded by the number of candidates
drawn, so infeasible settings end with fewer vehicles instead of looping.

`PaperSpawner` runs these rules candidate by candidate inside one kernel call
(`_sim.placement.Placer`, on the same `ChunkKernel.pose`); `sample_on_chunks` and
`greedy_separated` are the batch forms, for other placements and the tests.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from selfplaydrive.scenario.index import Chunks, MapIndex


@dataclass
class Poses:
    """Candidate vehicle poses on lanes.

    Attributes:
        lane: (n,) int64 lane index.
        s: (n,) float64 arc length on the lane [m].
        xy: (n, 2) float64 [m] box centre.
        heading: (n,) float64 [rad].
        chunk: (n,) int64 index of the chunk the pose came from.
    """

    lane: np.ndarray
    s: np.ndarray
    xy: np.ndarray
    heading: np.ndarray
    chunk: np.ndarray

    def take(self, idx: np.ndarray) -> Poses:
        """The poses at `idx`."""
        return Poses(self.lane[idx], self.s[idx], self.xy[idx], self.heading[idx], self.chunk[idx])

    def concat(self, other: Poses) -> Poses:
        """These poses followed by `other`."""
        return Poses(
            *(
                np.concatenate([getattr(self, f), getattr(other, f)])
                for f in ("lane", "s", "xy", "heading", "chunk")
            )
        )


def region_box(centre: np.ndarray, size: float) -> np.ndarray:
    """(4,) float64 xmin, ymin, xmax, ymax of a square of edge `size` [m] around `centre`."""
    h = size / 2
    return np.array([centre[0] - h, centre[1] - h, centre[0] + h, centre[1] + h])


def sample_region(index: MapIndex, rng: np.random.Generator) -> np.ndarray:
    """A random region: a uniformly chosen candidate centre, jittered by +-stride/2 per axis.

    Raises:
        ValueError: When the map has no spawnable lane at all.
    """
    if len(index.centres) == 0:
        raise ValueError(
            f"map {index.road_map.name!r} has no spawnable lane (vehicle or bus lanes outside junctions)"
        )
    u = rng.random(3)
    centre = index.centres[min(int(u[0] * len(index.centres)), len(index.centres) - 1)]
    centre = centre + (u[1:] - 0.5) * index.region_stride
    return region_box(centre, index.region_size)


def sample_on_chunks(
    index: MapIndex, chunks: Chunks, box: np.ndarray, rng: np.random.Generator, n: int
) -> Poses:
    """Up to `n` poses uniform over the length of the chunks whose midpoint lies in `box`; poses
    outside `box` are dropped (chunks at the border stick out by up to half a chunk).

    Runs the fused Cython kernel `_sim.chunks.ChunkKernel.poses` (`sample_chunk_poses` on
    tables bound once per map); the NumPy twin is
    `testing.spawn_reference.sample_on_chunks_reference`. Draws (n, 2) uniforms from `rng`.
    """
    u = rng.random((max(n, 0), 2))
    box = np.ascontiguousarray(box, dtype=np.float64)
    lane, s, xy, heading, chunk = index.kernels.chunks(index, chunks).poses(box, u)
    return Poses(lane, s, xy, heading, chunk)


def greedy_separated(
    xy: np.ndarray,
    radius: np.ndarray,
    need: int,
    fixed_xy: np.ndarray | None = None,
    fixed_radius: np.ndarray | None = None,
    gap: float = 0.0,
) -> np.ndarray:
    """Greedy selection of candidates that keep apart from each other and from fixed objects
    (Cython kernel `_sim.placement.greedy_select`; NumPy twin
    `testing.spawn_reference.greedy_separated_reference`).

    Args:
        xy: (n, 2) candidate centres [m] in the order they are tried.
        radius: (n,) candidate radii [m].
        need: Stop after this many accepted.
        fixed_xy: (k, 2) centres of already placed objects [m].
        fixed_radius: (k,) their radii [m].
        gap: Extra clearance [m].

    Returns:
        (m,) int64 accepted candidate indices, m <= need, in acceptance order.
    """
    from selfplaydrive._sim.placement import greedy_select

    fx = (
        np.zeros((0, 2))
        if fixed_xy is None
        else np.ascontiguousarray(fixed_xy, dtype=np.float64).reshape(-1, 2)
    )
    fr = np.zeros(0) if fixed_radius is None else np.ascontiguousarray(fixed_radius, dtype=np.float64)
    return greedy_select(
        np.ascontiguousarray(xy, dtype=np.float64).reshape(-1, 2),
        np.ascontiguousarray(radius, dtype=np.float64),
        int(need),
        fx,
        fr,
        float(gap),
    )


def roadside_offset(
    lane_width: np.ndarray, edge: np.ndarray, width: np.ndarray, curb_gap: float, max_shoulder: float
) -> np.ndarray:
    """Lateral offset [m] to the right of the lane centreline for a vehicle parked at the roadside.

    The vehicle's right side goes `curb_gap` m inside the road edge; where no edge was found (or
    it is farther away), at most `max_shoulder` m beyond the lane's right border. The offset is
    never negative (a parked vehicle never sits left of the lane centre).

    Args:
        lane_width: (n,) [m].
        edge: (n,) distance from the centreline to the right road edge [m] (inf if none).
        width: (n,) vehicle widths [m].
        curb_gap: Clearance to the edge [m].
        max_shoulder: Largest distance of the vehicle's right side beyond the lane border [m].
    """
    right_side = np.minimum(edge - curb_gap, lane_width / 2 + max_shoulder)
    return np.maximum(right_side - width / 2, 0.0)


def offset_right(xy: np.ndarray, heading: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """(n, 2) points moved `offset` [m] to the right of `heading` [rad] (negative = left)."""
    return xy + offset[:, None] * np.stack([np.sin(heading), -np.cos(heading)], axis=1)


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """Angles wrapped into [-pi, pi) [rad]."""
    return (a + np.pi) % (2 * np.pi) - np.pi
