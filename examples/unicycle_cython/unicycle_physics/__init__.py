"""A physics model in Cython, packaged on its own (see pyproject.toml)."""

from __future__ import annotations

from selfplaydrive.physics import KernelPhysics
from selfplaydrive.sim.actions import DiscreteActions
from unicycle_physics import _kernel

ACCEL = (-4.0, -2.0, -1.0, 0.0, 1.0, 2.0, 3.0)  # [m/s^2]
YAW_RATE_DEG = (-40.0, -20.0, -10.0, -4.0, 0.0, 4.0, 10.0, 20.0, 40.0)  # [deg/s]


def unicycle(max_speed: float = 40.0, drag: float = 0.002) -> KernelPhysics:
    """The Cython function as a physics model with its own discrete action space."""
    actions = DiscreteActions(ACCEL, YAW_RATE_DEG).labelled(("accel", "yaw_rate"), ("m/s^2", "rad/s"))
    return KernelPhysics.from_cython(
        "unicycle_cython", _kernel, "unicycle", args=(max_speed, drag), actions=actions,
        accepts=("discrete",), max_speed=max_speed,
    )  # fmt: skip
