"""The physics-model contract (paper section 2.6; docs/architecture.md "Protocols").

A physics model advances the agents' poses and speeds by one step. The kernel models select a
Cython or compiled kernel once, at construction, through the `Params` fields they fill; an
external model (`ExternalPhysicsModel`) is stepped in Python before the kernels instead.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol, runtime_checkable

if TYPE_CHECKING:
    import numpy as np

__all__ = ["ExternalPhysicsModel", "PhysicsModel"]


@runtime_checkable
class PhysicsModel(Protocol):
    """Anything with ``kernel_params() -> dict``: the physics fields of the step's `Params`.

    Contract every implementation keeps:

    - The constructor validates its arguments (`ConfigError` naming the key and range).
    - ``kernel_params()`` returns the same dict on every call (at least ``physics``, the kernel
      selector, and ``max_speed`` [m/s]); the env reads it once, at construction.
    - The kernel it selects writes only the pose and speed arrays of the world it is given
      (x, y, heading, hcos, hsin, speed, the previous-pose copies, a_long, a_lat, dist), is
      deterministic and depends on no other world.
    """

    def kernel_params(self) -> dict[str, object]:
        """The physics fields of the `Params` struct (names as in _sim/common.pxd)."""
        ...


@runtime_checkable
class ExternalPhysicsModel(PhysicsModel, Protocol):
    """A model stepped in Python before the kernels (``external = True``; `PymunkModel`).

    The kernels skip their physics stage for it; ``step`` updates the env's buffers in place.
    """

    @property
    def external(self) -> bool:
        """True: the env calls `step` and its kernels skip the physics stage."""
        ...

    def step(self, buffers: dict[str, np.ndarray], dt: float, accel: np.ndarray, steer: np.ndarray) -> None:
        """Advance every active agent of `buffers` by `dt` [s] under (N,) `accel` [m/s^2] and
        `steer` [rad] (before the hidden gains)."""
        ...
