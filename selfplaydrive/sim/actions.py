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

    Attributes:
        names: What the two columns mean to the physics model: ("accel", "steer"), or another
            model's meaning (`JerkBicycleModel` reads the tables as changes; `labelled`).
        units: Units of the table values as the kernels receive them.
    """

    discrete = True
    dim = 2

    def __init__(
        self,
        accel: Sequence[float] = ACCEL_VALUES,
        steer_deg: Sequence[float] = STEER_DEGREES,
    ) -> None:
        self.accel = _table(accel, "accel")
        self.steer = np.deg2rad(_table(steer_deg, "steer_deg")).astype(np.float32)
        if np.any(np.abs(self.steer) >= np.pi / 2):
            raise ValueError(f"steer_deg: every angle must lie in (-90, 90) degrees, got {list(steer_deg)}")
        self.names, self.units = ("accel", "steer"), ("m/s^2", "rad")

    def labelled(self, names: Sequence[str], units: Sequence[str]) -> DiscreteActions:
        """This table with the column names and units of another physics model (returns self)."""
        self.names, self.units = _labels(names, units, 2)
        return self

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
        sizes = (len(self.accel), len(self.steer))
        for col, (name, n) in enumerate(zip(map(_long_name, self.names), sizes, strict=True)):
            bad = (a[:, col] < 0) | (a[:, col] >= n)
            if bad.any():
                i = int(np.argmax(bad))
                raise ValueError(
                    f"actions[{i}, {col}] ({name} index) = {a[i, col]}: expected an integer in [0, {n})"
                )
        return np.ascontiguousarray(a, dtype=np.int32)


class BoxActions:
    """Box actions of any dimension within [low, high] per column (continuous).

    Args:
        low: Lower bound of each column, in the units the kernel receives.
        high: Upper bound of each column (> low).
        names: Name of each column (e.g. ("dx", "dy", "dyaw")).
        units: Unit of each column (e.g. ("m", "m", "rad")).
    """

    discrete = False

    def __init__(
        self, low: Sequence[float], high: Sequence[float], names: Sequence[str], units: Sequence[str]
    ) -> None:
        lo, hi = np.asarray(low, dtype=np.float64), np.asarray(high, dtype=np.float64)
        if lo.ndim != 1 or lo.shape != hi.shape or len(lo) == 0:
            raise ValueError(f"low, high: expected two 1-D lists of equal length, got {low!r}, {high!r}")
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(lo < hi)):
            raise ValueError(f"low, high: expected finite bounds with low < high, got {low!r}, {high!r}")
        self.low = lo.astype(np.float32)
        self.high = hi.astype(np.float32)
        self.dim = len(lo)
        self.names, self.units = _labels(names, units, self.dim)
        self.accel = np.zeros(1, dtype=np.float32)  # no value tables (Params.accel_table)
        self.steer = np.zeros(1, dtype=np.float32)

    @property
    def space(self) -> gym.spaces.Box:
        return gym.spaces.Box(self.low, self.high, dtype=np.float32)

    def validate(self, actions: object, num_agents: int) -> np.ndarray:
        """Return `actions` as a C-contiguous (num_agents, dim) float32 array or raise ValueError."""
        a = _shape_checked(actions, num_agents, self.dim)
        if a.dtype.kind != "f":
            raise ValueError(f"actions: expected a float array (Box), got dtype {a.dtype}")
        if not np.all(np.isfinite(a)):
            i, j = np.argwhere(~np.isfinite(a))[0]
            raise ValueError(f"actions[{i}, {j}] = {a[i, j]}: expected a finite number")
        tol = 1e-6 * np.maximum(np.abs(self.low), np.abs(self.high))
        over = (a < self.low - tol) | (a > self.high + tol)
        if over.any():
            i, j = np.argwhere(over)[0]
            raise ValueError(
                f"actions[{i}, {j}] = {a[i, j]}: expected a value in "
                f"[{self.low[j]}, {self.high[j]}] {self.units[j]} ({self.names[j]})"
            )
        return np.ascontiguousarray(a, dtype=np.float32)


class ContinuousActions(BoxActions):
    """Box actions: (acceleration [m/s^2], steering [rad]) within symmetric limits.

    Args:
        max_accel: Largest |acceleration| [m/s^2].
        max_steer_deg: Largest |steering angle| [deg].
    """

    def __init__(self, max_accel: float = 4.0, max_steer_deg: float = 38.0) -> None:
        if not (0 < max_accel < 100 and 0 < max_steer_deg < 90):
            raise ValueError(
                f"max_accel: expected (0, 100), max_steer_deg: expected (0, 90); "
                f"got {max_accel}, {max_steer_deg}"
            )
        high = np.array([max_accel, np.deg2rad(max_steer_deg)], dtype=np.float32)
        super().__init__(-high, high, ("accel", "steer"), ("m/s^2", "rad"))


def _table(values: Sequence[float], name: str) -> np.ndarray:
    t = np.asarray(values, dtype=np.float64)
    if t.ndim != 1 or len(t) == 0 or not np.all(np.isfinite(t)):
        raise ValueError(f"{name}: expected a non-empty 1-D list of finite numbers, got {values!r}")
    return t.astype(np.float32)


def _long_name(name: str) -> str:
    return {"accel": "acceleration", "steer": "steering"}.get(name, name)


def _labels(names: Sequence[str], units: Sequence[str], dim: int) -> tuple[tuple[str, ...], tuple[str, ...]]:
    n, u = tuple(str(x) for x in names), tuple(str(x) for x in units)
    if len(n) != dim or len(u) != dim:
        raise ValueError(f"names, units: expected {dim} of each (one per action column), got {n!r}, {u!r}")
    return n, u


def _shape_checked(actions: object, num_agents: int, dim: int = 2) -> np.ndarray:
    if not isinstance(actions, np.ndarray):
        raise ValueError(
            f"actions: expected a numpy array of shape ({num_agents}, {dim}), got {type(actions).__name__}"
        )
    if actions.shape != (num_agents, dim):
        raise ValueError(f"actions: expected shape ({num_agents}, {dim}), got {actions.shape}")
    return actions
