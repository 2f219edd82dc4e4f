"""The library's physics models (section 2.6): components of the ABI's `sd_physics_fn`, their
kernels in _sim/physics.pyx, their NumPy references in selfplaydrive/testing/physics_reference.py.

| model                  | actions (columns, units)                        | state          |
|------------------------|-------------------------------------------------|----------------|
| `BicycleModel`         | env's: accel [m/s^2], steer [rad]               | -              |
| `FrictionBicycleModel` | env's: accel [m/s^2], steer [rad] (default)     | -              |
| `JerkBicycleModel`     | d_accel [m/s^2 per step], d_steer [rad per step] | accel, steer   |
| `DeltaModel`           | dx [m], dy [m] (agent frame), dyaw [rad]        | -              |
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence

import numpy as np

from selfplaydrive.errors import ConfigError
from selfplaydrive.physics.components import PhysicsModel

PHYS_BICYCLE = 0  # SD_PHYS_* of selfplaydrive_abi.h
PHYS_FRICTION = 1

# jerk-limited model: per-step changes of the commanded acceleration [m/s^2] and steering
# [deg]; 0.5 m/s^2 per 0.1 s step is a jerk of 5 m/s^3 (comfortable driving stays below ~2,
# an emergency stop reaches ~10), the steering changes span a slow lane change to a sharp turn
JERK_ACCEL_DELTAS = (-2.0, -1.0, -0.5, 0.0, 0.5, 1.0, 2.0)
JERK_STEER_DELTAS_DEG = (-8.0, -4.0, -2.0, -1.0, 0.0, 1.0, 2.0, 4.0, 8.0)


@functools.lru_cache(maxsize=1)
def _addresses() -> dict[str, int]:
    from selfplaydrive._sim import physics as kernels

    return {k: int(v) for k, v in kernels.model_addresses().items()}


def _check(name: str, value: float, low: float, high: float, unit: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = math.nan
    if not (low < v <= high):
        raise ConfigError(f"physics.{name}: expected a value in ({low}, {high}] {unit}, got {value!r}")
    return v


class BicycleModel(PhysicsModel):
    """Kinematic bicycle model, no friction limit.

    The box centre is the reference point with the axles symmetric about it: slip angle
    beta = atan(tan(delta) / 2), path curvature kappa = 2 sin(beta) / wheelbase, so constant
    steering gives a circle of radius 1 / kappa. Hidden gains multiply every action. Reads the
    env's (acceleration [m/s^2], steering [rad]) actions, discrete or continuous.

    Args:
        wheelbase_ratio: Wheelbase / box length (0.6: a 4.5 m car has a 2.7 m wheelbase).
        max_speed: Speed clamp [m/s]; also the observation scale of speeds. Speeds stay >= 0.
    """

    name = "bicycle"
    kernel = PHYS_BICYCLE

    def __init__(self, wheelbase_ratio: float = 0.6, max_speed: float = 40.0) -> None:
        if not (0 < wheelbase_ratio <= 1.5):
            raise ConfigError(
                f"physics.wheelbase_ratio: expected a value in (0, 1.5], got {wheelbase_ratio!r}"
            )
        if not (0 < max_speed < 200):
            raise ConfigError(f"physics.max_speed: expected a value in (0, 200) m/s, got {max_speed!r}")
        self.wheelbase_ratio = float(wheelbase_ratio)
        self.max_speed = float(max_speed)
        self.gravity = 9.81

    def address(self) -> int:
        return _addresses()[self.name]

    def args(self) -> tuple[float, ...]:
        """_sim/physics.pyx BICYCLE_ARGS: wheelbase_ratio, max_speed, gravity."""
        return (self.wheelbase_ratio, self.max_speed, self.gravity)

    def radius(self, length: float, steer: float) -> float:
        """Radius [m] of the centre's circle at steering angle `steer` [rad] (no friction limit)."""
        tb = 0.5 * math.tan(steer)
        return self.wheelbase_ratio * length / (2.0 * abs(tb) / math.sqrt(1.0 + tb * tb))


class FrictionBicycleModel(BicycleModel):
    """Bicycle model with the friction limit of section 2.6 (the default).

    When sqrt(a_long^2 + a_lat^2) exceeds mu g (mu per vehicle, hidden), both components are
    scaled by mu g / |a|: the car brakes or accelerates less and follows a larger radius.

    Args:
        wheelbase_ratio: Wheelbase / box length.
        max_speed: Speed clamp [m/s].
        gravity: g [m/s^2].
    """

    name = "friction"
    kernel = PHYS_FRICTION

    def __init__(self, wheelbase_ratio: float = 0.6, max_speed: float = 40.0, gravity: float = 9.81) -> None:
        super().__init__(wheelbase_ratio, max_speed)
        if not (0 < gravity < 100):
            raise ConfigError(f"physics.gravity: expected a value in (0, 100) m/s^2, got {gravity!r}")
        self.gravity = float(gravity)


class JerkBicycleModel(PhysicsModel):
    """Jerk-limited bicycle (Gigaflow; PufferDrive 3.0): actions are CHANGES of the commanded
    acceleration and steering, so no policy can jump from full throttle to full braking in one
    step. The model owns the commanded acceleration and steering of every agent (state columns
    "accel" [m/s^2], "steer" [rad]; 0 at spawn), adds the action's deltas, clamps to
    [-max_accel, max_accel] and [-max_steer, max_steer], and moves the car with the bicycle
    geometry (friction limit optional) and the hidden gains, like `FrictionBicycleModel`.

    Args:
        accel_deltas: Discrete changes of acceleration per step [m/s^2].
        steer_deltas_deg: Discrete changes of steering per step [deg].
        max_accel: Bound of the commanded |acceleration| [m/s^2].
        max_steer_deg: Bound of the commanded |steering| [deg].
        friction: Apply the friction limit mu g (section 2.6).
        wheelbase_ratio: Wheelbase / box length.
        max_speed: Speed clamp [m/s].
        gravity: g [m/s^2].
    """

    name = "jerk"
    state_dim = 2
    state_names = ("accel", "steer")

    def __init__(
        self,
        accel_deltas: Sequence[float] = JERK_ACCEL_DELTAS,
        steer_deltas_deg: Sequence[float] = JERK_STEER_DELTAS_DEG,
        max_accel: float = 4.0,
        max_steer_deg: float = 38.0,
        friction: bool = True,
        wheelbase_ratio: float = 0.6,
        max_speed: float = 40.0,
        gravity: float = 9.81,
    ) -> None:
        self.max_accel = _check("max_accel", max_accel, 0.0, 100.0, "m/s^2")
        self.max_steer = math.radians(_check("max_steer_deg", max_steer_deg, 0.0, 89.0, "deg"))
        self.wheelbase_ratio = _check("wheelbase_ratio", wheelbase_ratio, 0.0, 1.5, "")
        self.max_speed = _check("max_speed", max_speed, 0.0, 199.0, "m/s")
        self.gravity = _check("gravity", gravity, 0.0, 99.0, "m/s^2")
        self.friction = bool(friction)
        from selfplaydrive.sim.actions import DiscreteActions  # sim/ imports physics/

        try:
            self.actions = DiscreteActions(accel_deltas, steer_deltas_deg).labelled(
                ("d_accel", "d_steer"), ("m/s^2 per step", "rad per step")
            )
        except ValueError as exc:
            raise ConfigError(f"physics.accel_deltas / steer_deltas_deg: {exc}") from None

    def address(self) -> int:
        return _addresses()["jerk"]

    def args(self) -> tuple[float, ...]:
        """_sim/physics.pyx JERK_ARGS."""
        return (
            self.wheelbase_ratio,
            self.max_speed,
            self.gravity,
            float(self.friction),
            self.max_accel,
            self.max_steer,
        )


class DeltaModel(PhysicsModel):
    """Waymax-style delta model ("DeltaLocal"): the action is the motion itself, (dx, dy) [m]
    in the agent's frame at the start of the step and dyaw [rad], continuous and bounded. The
    speed becomes |(dx, dy)| / dt; `inverse` recovers the action from two consecutive states
    (for replaying logged or scripted motion). No hidden gains: the model has no actuators.

    Args:
        max_forward: Largest dx per step [m] (3.5 m = 35 m/s at dt 0.1 s).
        max_backward: Largest backward motion per step [m] (dx >= -max_backward; 0: none).
        max_lateral: Largest |dy| per step [m].
        max_yaw_deg: Largest |dyaw| per step [deg].
        max_speed: Speed clamp [m/s]: a longer step is shortened to max_speed * dt.
    """

    name = "delta"
    accepts = ("continuous",)

    def __init__(
        self,
        max_forward: float = 3.5,
        max_backward: float = 0.0,
        max_lateral: float = 0.5,
        max_yaw_deg: float = 20.0,
        max_speed: float = 40.0,
    ) -> None:
        self.max_forward = _check("max_forward", max_forward, 0.0, 50.0, "m")
        if not (0.0 <= float(max_backward) <= 50.0):
            raise ConfigError(f"physics.max_backward: expected a value in [0, 50] m, got {max_backward!r}")
        self.max_backward = float(max_backward)
        self.max_lateral = _check("max_lateral", max_lateral, 0.0, 50.0, "m")
        self.max_yaw = math.radians(_check("max_yaw_deg", max_yaw_deg, 0.0, 180.0, "deg"))
        self.max_speed = _check("max_speed", max_speed, 0.0, 199.0, "m/s")
        from selfplaydrive.sim.actions import BoxActions  # sim/ imports physics/

        low = (-self.max_backward if self.max_backward > 0 else 0.0, -self.max_lateral, -self.max_yaw)
        self.actions = BoxActions(
            low, (self.max_forward, self.max_lateral, self.max_yaw), ("dx", "dy", "dyaw"), ("m", "m", "rad")
        )

    def address(self) -> int:
        return _addresses()["delta"]

    def args(self) -> tuple[float, ...]:
        """_sim/physics.pyx DELTA_ARGS: max_speed."""
        return (self.max_speed,)

    @staticmethod
    def inverse(
        x0: np.ndarray, y0: np.ndarray, h0: np.ndarray, x1: np.ndarray, y1: np.ndarray, h1: np.ndarray
    ) -> np.ndarray:
        """The (N, 3) float32 actions (dx, dy, dyaw) that move states 0 to states 1: the
        displacement rotated into the frame of heading h0, and the wrapped heading change.

        Args:
            x0, y0, h0: (N,) positions [m] and headings [rad] before the step.
            x1, y1, h1: (N,) after it.
        """
        x0, y0, h0, x1, y1, h1 = (np.asarray(v, dtype=np.float64) for v in (x0, y0, h0, x1, y1, h1))
        ex, ey = x1 - x0, y1 - y0
        c, s = np.cos(h0), np.sin(h0)
        dyaw = np.angle(np.exp(1j * (h1 - h0)))
        return np.stack([c * ex + s * ey, -s * ex + c * ey, dyaw], axis=1).astype(np.float32)
