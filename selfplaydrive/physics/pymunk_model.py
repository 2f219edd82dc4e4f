"""Rigid-body vehicle model on pymunk, for physics ablations (design: physics/, section 2.6).

Slow by design (a Python loop over agents each step) and off the hot path: `VecEnv` runs it
before the Cython kernels, which then skip their own dynamics (kernel `PHYS_EXTERNAL`) and
run collisions, road events, rewards and observations on the moved vehicles as usual.

What the model does, per active agent and step dt:

1. The action gives acceleration a and steering delta (times the hidden gains, as in the
   bicycle models). The target speed is v1 = clip(v0 + a dt, 0, max_speed) and the path
   curvature of the bicycle geometry is kappa = 2 sin(beta) / wheelbase with
   tan(beta) = tan(delta) / 2.
2. The vehicle is a pymunk body (mass `mass` [kg], box moment of inertia) at the box centre,
   heading theta, velocity v0 along theta. Two tire forces act at its centre: longitudinal
   F_long = m (v1 - v0) / dt along theta and lateral (centripetal) F_lat = m v1^2 kappa to the
   left of theta. When |F| exceeds mu m g (mu: hidden friction) both are scaled down by
   mu m g / |F| (friction circle: the car understeers and accelerates or brakes less).
3. Yaw is velocity-controlled: angular velocity = v1 kappa_eff, kappa_eff being the
   curvature after the friction scaling.
4. pymunk integrates one step (semi-implicit Euler). The new speed is the velocity's component
   along the new heading, clamped to [0, max_speed] (no reversing); the realised
   accelerations a_long = (v - v0) / dt and a_lat = F_lat / m feed the comfort term.

Vehicles do not collide inside pymunk (no shapes): collisions stay the simulator's event on
the true boxes, as with the kinematic models.
"""

from __future__ import annotations

import math

import numpy as np

from selfplaydrive._optional import requires_extra
from selfplaydrive.errors import ConfigError
from selfplaydrive.physics.models import BicycleModel

PHYS_EXTERNAL = 2  # _sim/common.pxd: the kernel leaves the dynamics to Python


VEHICLE_MASS = 1500.0  # [kg]; cancels out of the motion (see PymunkModel)


class PymunkModel(BicycleModel):
    """Rigid-body vehicles in a pymunk space driven by bicycle-like tire forces.

    Args:
        wheelbase_ratio: Wheelbase / box length.
        max_speed: Speed clamp [m/s].
        gravity: g of the friction circle [m/s^2].

    Every vehicle has the same mass (`VEHICLE_MASS`): the tire forces are computed from the
    requested accelerations times the mass, so the mass cancels out of the motion and is not a
    parameter (a key that changes nothing would be a silently ignored setting).
    """

    name = "pymunk"
    kernel = PHYS_EXTERNAL
    external = True  # the Python/NumPy form of a physics component: no kernel address

    def __init__(
        self,
        wheelbase_ratio: float = 0.6,
        max_speed: float = 40.0,
        gravity: float = 9.81,
    ) -> None:
        super().__init__(wheelbase_ratio, max_speed)
        if not (0 < gravity < 100):
            raise ConfigError(f"physics.gravity: expected a value in (0, 100) m/s^2, got {gravity!r}")
        with requires_extra("pymunk"):
            import pymunk

        self._pymunk = pymunk
        self.gravity = float(gravity)
        self.mass = VEHICLE_MASS
        self._space = pymunk.Space()
        self._bodies: list = []

    def address(self) -> int:
        return 0  # stepped in Python before the kernels (`step`)

    def _body(self, k: int):
        pm = self._pymunk
        while len(self._bodies) <= k:
            body = pm.Body(self.mass, 1.0)
            self._space.add(body)
            self._bodies.append(body)
        return self._bodies[k]

    def step(self, b: dict[str, np.ndarray], dt: float, accel: np.ndarray, steer: np.ndarray) -> None:
        """Advance every active agent of the env buffers `b` by dt [s].

        Args:
            b: The env's buffers (sim/buffers.py); x, y, heading, hcos, hsin, speed, px, py,
                pheading, a_long, a_lat and dist are updated in place.
            dt: Step length [s].
            accel: (N,) requested acceleration [m/s^2] before the hidden gain.
            steer: (N,) steering angle [rad] before the hidden gain.
        """
        b["px"][:] = b["x"]
        b["py"][:] = b["y"]
        b["pheading"][:] = b["heading"]
        b["a_long"][:] = 0.0
        b["a_lat"][:] = 0.0
        active = np.flatnonzero(b["active"])
        if len(active) == 0:
            return
        plan = self._forces(b, dt, active, accel, steer)
        for k, i in enumerate(active):
            self._place(k, b, int(i), plan[k])
        self._space.step(dt)
        self._read_back(b, dt, active, plan)

    def _forces(self, b, dt, active, accel, steer) -> np.ndarray:
        """(n, 5) float64 per active agent: F_long, F_lat [N], yaw rate [rad/s], v0, v1 [m/s]."""
        h = b["hidden"][active].astype(np.float64)
        acc = accel[active].astype(np.float64) * h[:, 1]
        delta = steer[active].astype(np.float64) * h[:, 2]
        v0 = b["speed"][active].astype(np.float64)
        v1 = np.clip(v0 + acc * dt, 0.0, self.max_speed)
        tb = 0.5 * np.tan(delta)
        kappa = 2.0 * (tb / np.sqrt(1.0 + tb * tb)) / (self.wheelbase_ratio * b["length"][active])
        f_long = self.mass * (v1 - v0) / dt
        f_lat = self.mass * v1 * v1 * kappa
        limit = h[:, 0] * self.mass * self.gravity
        norm = np.hypot(f_long, f_lat)
        scale = np.where(norm > limit, limit / np.maximum(norm, 1e-12), 1.0)
        f_long, f_lat, kappa = f_long * scale, f_lat * scale, kappa * scale
        v1 = np.clip(v0 + f_long / self.mass * dt, 0.0, self.max_speed)
        return np.stack([f_long, f_lat, v1 * kappa, v0, v1], axis=1)

    def _place(self, k: int, b, i: int, plan: np.ndarray) -> None:
        f_long, f_lat, yaw_rate, v0, _ = (float(v) for v in plan)
        body = self._body(k)
        th = float(b["heading"][i])
        c, s = math.cos(th), math.sin(th)
        length, width = float(b["length"][i]), float(b["width"][i])
        body.moment = self.mass * (length * length + width * width) / 12.0
        body.position = (float(b["x"][i]), float(b["y"][i]))
        body.angle = th
        body.velocity = (v0 * c, v0 * s)
        body.angular_velocity = yaw_rate
        body.force = (f_long * c - f_lat * s, f_long * s + f_lat * c)
        body.torque = 0.0

    def _read_back(self, b, dt: float, active: np.ndarray, plan: np.ndarray) -> None:
        n = len(active)
        pos = np.array([self._bodies[k].position for k in range(n)], dtype=np.float64)
        vel = np.array([self._bodies[k].velocity for k in range(n)], dtype=np.float64)
        ang = np.array([self._bodies[k].angle for k in range(n)], dtype=np.float64)
        ang = np.arctan2(np.sin(ang), np.cos(ang))
        c, s = np.cos(ang), np.sin(ang)
        v = np.clip(vel[:, 0] * c + vel[:, 1] * s, 0.0, self.max_speed)
        b["x"][active] = pos[:, 0]
        b["y"][active] = pos[:, 1]
        b["heading"][active] = ang
        b["hcos"][active] = c
        b["hsin"][active] = s
        b["speed"][active] = v
        b["a_long"][active] = (v - plan[:, 3]) / dt
        b["a_lat"][active] = plan[:, 1] / self.mass
        A = len(b["x"]) // len(b["dist"])
        np.add.at(b["dist"], active // A, v * dt)
