"""Observation layout (paper section 2.5): offsets and feature names that models read.

A row is [ego | objects | road | extra]: `EGO_FEATURES`, then `max_objects` blocks of
`OBJECT_FEATURES`, then `max_road` blocks of `ROAD_FEATURES`, then the columns of Python
observation hooks. The layout belongs to the observation encoder (obs/encoders.py): an encoder
declares it, the env sizes its buffers from it, the models build from it (`blocks()`: named
blocks with shapes). An encoder may leave a block empty (`max_road=0`: no road rows). Every
encoder-written value lies in [-bound, bound] (the paper's: [-1, 1], scaled, then clipped);
padded object and road slots are all zeros, their `valid` feature 0. The orders below must
match _sim/observe.pyx (EGO_DIM, OBJ_DIM, ROAD_DIM in _sim/common.pxd).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

EGO_FEATURES = (
    "width",  # [m] / width_scale
    "length",  # [m] / length_scale
    "speed",  # [m/s] / max_speed
    "wp0_dx",  # current waypoint, ego frame (x forward) [m] / wp_scale
    "wp0_dy",  # (y left)
    "wp1_dx",  # next waypoint (= current when it is the last) [m] / wp_scale
    "wp1_dy",
    "wp_remaining",  # waypoints left / K
    "lane_s",  # signed lateral offset from the lane centre, + right [m] / lateral_scale
    "lane_alpha",  # heading minus lane direction, + left [rad] / pi
    "lane_valid",  # 1 when a centerline lies within lane_radius
    "coef_waypoint_radius",  # the reward coefficients (scenario.types.COEFF_NAMES) / coeff_scale
    "coef_collision",
    "coef_offroad",
    "coef_red_light",
    "coef_comfort",
    "coef_center",
    "coef_center_bias",
    "coef_align",
)
OBJECT_FEATURES = (
    "valid",  # 1 for an object, 0 for padding
    "dx",  # centre, ego frame [m] / pos_scale
    "dy",
    "cos_heading",  # cos and sin of the object's heading relative to the ego heading
    "sin_heading",
    "length",  # [m] / length_scale
    "width",  # [m] / width_scale
    "vx",  # velocity in the ego frame [m/s] / max_speed
    "vy",
)
ROAD_FEATURES = (
    "valid",  # 1 for a segment, 0 for padding
    "dx",  # midpoint, ego frame [m] / pos_scale
    "dy",
    "cos_dir",  # segment direction relative to the ego heading
    "sin_dir",
    "length",  # [m] / length_scale
    "type",  # SegmentType / 4: lane 0, edge 0.25, stop 0.5, light 0.75, crosswalk 1
    "light_state",  # traffic-light lines: off 0, red 1/3, yellow 2/3, green 1; others 0
)


@dataclass(frozen=True)
class ObsLayout:
    """Where each block of an observation row lies.

    Attributes:
        max_objects: Object slots (63 in the paper).
        max_road: Road-segment slots (200 in the paper).
        extra_dim: Columns appended by Python observation hooks.
        bound: The encoder's columns lie in [-bound, bound] (1 for the library's encoders).
    """

    max_objects: int = 63
    max_road: int = 200
    extra_dim: int = 0
    bound: float = 1.0

    def __post_init__(self) -> None:
        for key in ("max_objects", "max_road", "extra_dim"):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
                raise ValueError(f"layout {key}: expected an integer >= 0, got {v!r}")
        if isinstance(self.bound, bool) or not 0 < float(self.bound) < float("inf"):
            raise ValueError(f"layout bound: expected a finite number > 0, got {self.bound!r}")

    def blocks(self) -> dict[str, tuple[int, ...]]:
        """Named blocks of a row with their shapes, in column order: ego (E,), objects (O, F),
        road (R, F), extra (X,)."""
        return {
            "ego": (self.ego_dim,),
            "objects": (self.max_objects, self.object_dim),
            "road": (self.max_road, self.road_dim),
            "extra": (self.extra_dim,),
        }

    @property
    def ego_dim(self) -> int:
        return len(EGO_FEATURES)

    @property
    def object_dim(self) -> int:
        return len(OBJECT_FEATURES)

    @property
    def road_dim(self) -> int:
        return len(ROAD_FEATURES)

    @property
    def objects_offset(self) -> int:
        return self.ego_dim

    @property
    def road_offset(self) -> int:
        return self.objects_offset + self.max_objects * self.object_dim

    @property
    def extra_offset(self) -> int:
        return self.road_offset + self.max_road * self.road_dim

    @property
    def kernel_dim(self) -> int:
        """Columns written by the Cython kernels."""
        return self.extra_offset

    @property
    def obs_dim(self) -> int:
        return self.extra_offset + self.extra_dim

    def split(self, obs: np.ndarray) -> dict[str, np.ndarray]:
        """Views of (N, obs_dim) observations: ego (N, E), objects (N, O, F), road (N, R, F), extra."""
        n = obs.shape[0]
        return {
            "ego": obs[:, : self.ego_dim],
            "objects": obs[:, self.objects_offset : self.road_offset].reshape(
                n, self.max_objects, self.object_dim
            ),
            "road": obs[:, self.road_offset : self.extra_offset].reshape(n, self.max_road, self.road_dim),
            "extra": obs[:, self.extra_offset :],
        }

    def feature_index(self, block: str, name: str) -> int:
        """Column of feature `name` within one element of `block` ('ego', 'object', 'road')."""
        names = {"ego": EGO_FEATURES, "object": OBJECT_FEATURES, "road": ROAD_FEATURES}
        if block not in names:
            raise ValueError(f"block: expected one of {sorted(names)}, got {block!r}")
        if name not in names[block]:
            raise ValueError(f"{block} feature: expected one of {names[block]}, got {name!r}")
        return names[block].index(name)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(low, high) float32 arrays of the observation Box: [-bound, bound] for the encoder's
        columns, unbounded (+-inf is not allowed in Box checks, so +-1e6) for hook columns."""
        low = np.full(self.obs_dim, -self.bound, dtype=np.float32)
        high = np.full(self.obs_dim, self.bound, dtype=np.float32)
        low[self.kernel_dim :] = -1e6
        high[self.kernel_dim :] = 1e6
        return low, high
