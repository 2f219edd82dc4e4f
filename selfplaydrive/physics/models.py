"""Kinematic bicycle models (section 2.6); the kernels are in _sim/physics.pyx."""

from __future__ import annotations

import math

from selfplaydrive.errors import ConfigError

PHYS_BICYCLE = 0  # _sim/common.pxd
PHYS_FRICTION = 1


class BicycleModel:
    """Kinematic bicycle model, no friction limit.

    The box centre is the reference point with the axles symmetric about it: slip angle
    beta = atan(tan(delta) / 2), path curvature kappa = 2 sin(beta) / wheelbase, so constant
    steering gives a circle of radius 1 / kappa. Hidden gains multiply every action.

    Args:
        wheelbase_ratio: Wheelbase / box length (0.6: a 4.5 m car has a 2.7 m wheelbase).
        max_speed: Speed clamp [m/s]; also the observation scale of speeds. Speeds stay >= 0.
    """

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

    def radius(self, length: float, steer: float) -> float:
        """Radius [m] of the centre's circle at steering angle `steer` [rad] (no friction limit)."""
        tb = 0.5 * math.tan(steer)
        return self.wheelbase_ratio * length / (2.0 * abs(tb) / math.sqrt(1.0 + tb * tb))

    def kernel_params(self) -> dict[str, object]:
        """The physics fields of the `Params` struct."""
        return {
            "physics": self.kernel,
            "wheelbase_ratio": self.wheelbase_ratio,
            "gravity": self.gravity,
            "max_speed": self.max_speed,
        }


class FrictionBicycleModel(BicycleModel):
    """Bicycle model with the friction limit of section 2.6 (the default).

    When sqrt(a_long^2 + a_lat^2) exceeds mu g (mu per vehicle, hidden), both components are
    scaled by mu g / |a|: the car brakes or accelerates less and follows a larger radius.

    Args:
        wheelbase_ratio: Wheelbase / box length.
        max_speed: Speed clamp [m/s].
        gravity: g [m/s^2].
    """

    kernel = PHYS_FRICTION

    def __init__(self, wheelbase_ratio: float = 0.6, max_speed: float = 40.0, gravity: float = 9.81) -> None:
        super().__init__(wheelbase_ratio, max_speed)
        if not (0 < gravity < 100):
            raise ConfigError(f"physics.gravity: expected a value in (0, 100) m/s^2, got {gravity!r}")
        self.gravity = float(gravity)
