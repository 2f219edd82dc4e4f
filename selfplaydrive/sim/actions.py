"""Action spaces (paper section 2.4) and the boundary checks run before any Cython call."""

from __future__ import annotations

from collections.abc import Sequence

import gymnasium as gym
import numpy as np

ACCEL_VALUES = (-4.0, -2.67, -1.33, 0.0, 1.33, 2.67, 4.0)  # [m/s^2], PufferDrive defaults
STEER_DEGREES = (-38.0, -29.0, -19.0, -10.0, -5.0, -2.0, 0.0, 2.0, 5.0, 10.0, 19.0, 29.0, 38.0)  # [deg]


class DiscreteActions:
    """MultiDiscrete (acceleration index, steering index) over two value tables.

    Args:
        accel: Acceleration values [m/s^2] (7 in the paper).
        steer_deg: Steering angles [deg], positive = left (13 in the paper).
    """

    discrete = True

    def __init__(
        self, accel: Sequence[float] = ACCEL_VALUES, steer_deg: Sequence[float] = STEER_DEGREES
    ) -> None:
        self.accel = _table(accel, "accel")
        self.steer = np.deg2rad(_table(steer_deg, "steer_deg")).astype(np.float32)
        if np.any(np.abs(self.steer) >= np.pi / 2):
            raise ValueError(f"steer_deg: every angle must lie in (-90, 90) degrees, got {list(steer_deg)}")

    @property
    def space(self) -> gym.spaces.MultiDiscrete:
        return gym.spaces.MultiDiscrete([len(self.accel), len(self.steer)])

    def validate(self, actions: object, num_agents: int) -> np.ndarray:
        """Return `actions` as a C-contiguous (num_agents, 2) int32 array or raise ValueError."""
        a = _shape_checked(actions, num_agents)
        if a.dtype.kind not in "iu":
            raise ValueError(
                f"actions: expected an integer array (MultiDiscrete indices), got dtype {a.dtype}"
            )
        for col, (name, n) in enumerate((("acceleration", len(self.accel)), ("steering", len(self.steer)))):
            bad = (a[:, col] < 0) | (a[:, col] >= n)
            if bad.any():
                i = int(np.argmax(bad))
                raise ValueError(
                    f"actions[{i}, {col}] ({name} index) = {a[i, col]}: expected an integer in [0, {n})"
                )
        return np.ascontiguousarray(a, dtype=np.int32)


class ContinuousActions:
    """Box actions: (acceleration [m/s^2], steering [rad]) within symmetric limits.

    Args:
        max_accel: Largest |acceleration| [m/s^2].
        max_steer_deg: Largest |steering angle| [deg].
    """

    discrete = False

    def __init__(self, max_accel: float = 4.0, max_steer_deg: float = 38.0) -> None:
        if not (0 < max_accel < 100 and 0 < max_steer_deg < 90):
            raise ValueError(
                f"max_accel: expected (0, 100), max_steer_deg: expected (0, 90); "
                f"got {max_accel}, {max_steer_deg}"
            )
        self.high = np.array([max_accel, np.deg2rad(max_steer_deg)], dtype=np.float32)
        self.accel = np.zeros(1, dtype=np.float32)
        self.steer = np.zeros(1, dtype=np.float32)

    @property
    def space(self) -> gym.spaces.Box:
        return gym.spaces.Box(-self.high, self.high, dtype=np.float32)

    def validate(self, actions: object, num_agents: int) -> np.ndarray:
        """Return `actions` as a C-contiguous (num_agents, 2) float32 array or raise ValueError."""
        a = _shape_checked(actions, num_agents)
        if a.dtype.kind != "f":
            raise ValueError(f"actions: expected a float array (Box), got dtype {a.dtype}")
        if not np.all(np.isfinite(a)):
            i, j = np.argwhere(~np.isfinite(a))[0]
            raise ValueError(f"actions[{i}, {j}] = {a[i, j]}: expected a finite number")
        over = np.abs(a) > self.high * (1 + 1e-6)
        if over.any():
            i, j = np.argwhere(over)[0]
            raise ValueError(
                f"actions[{i}, {j}] = {a[i, j]}: expected a value in [{-self.high[j]}, {self.high[j]}]"
            )
        return np.ascontiguousarray(a, dtype=np.float32)


def _table(values: Sequence[float], name: str) -> np.ndarray:
    t = np.asarray(values, dtype=np.float64)
    if t.ndim != 1 or len(t) == 0 or not np.all(np.isfinite(t)):
        raise ValueError(f"{name}: expected a non-empty 1-D list of finite numbers, got {values!r}")
    return t.astype(np.float32)


def _shape_checked(actions: object, num_agents: int) -> np.ndarray:
    if not isinstance(actions, np.ndarray):
        raise ValueError(
            f"actions: expected a numpy array of shape ({num_agents}, 2), got {type(actions).__name__}"
        )
    if actions.shape != (num_agents, 2):
        raise ValueError(f"actions: expected shape ({num_agents}, 2), got {actions.shape}")
    return actions
