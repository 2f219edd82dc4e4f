"""Plain NumPy references of the physics components beyond the paper's bicycle (whose
reference is `reference.bicycle_step`), in float64, written from the rules in their
docstrings (_sim/physics.pyx, physics/models.py) and compared with the kernels on random
states in tests/sim/test_physics_components.py. None shares code with a kernel."""

from __future__ import annotations

import numpy as np

from selfplaydrive.testing.reference import bicycle_step

MAX_STEER = float(np.deg2rad(38.0))  # [rad], JerkBicycleModel's default bound


def jerk_step(
    x,
    y,
    heading,
    speed,
    length,
    cmd_accel,
    cmd_steer,
    d_accel,
    d_steer,
    hidden,
    dt=0.1,
    max_accel=4.0,
    max_steer=MAX_STEER,
    friction=True,
    wheelbase_ratio=0.6,
    max_speed=40.0,
    gravity=9.81,
):
    """One step of the jerk-limited bicycle: commanded acceleration / steering plus the
    action's changes, clamped to their bounds, then one bicycle step (gains applied).

    Returns:
        dict of (n,) float64: the bicycle's x, y, heading, speed, a_long, a_lat, and the new
        commanded accel and steer.
    """
    acc = np.clip(np.asarray(cmd_accel, np.float64) + d_accel, -max_accel, max_accel)
    steer = np.clip(np.asarray(cmd_steer, np.float64) + d_steer, -max_steer, max_steer)
    out = bicycle_step(
        x, y, heading, speed, length, acc, steer, hidden, dt, wheelbase_ratio, max_speed, gravity, friction
    )
    out.update(accel=acc, steer=steer)
    return out


def delta_step(x, y, heading, speed, dx, dy, dyaw, dt=0.1, max_speed=40.0):
    """One step of the delta model: move by (dx, dy) in the agent's frame (shortened to
    max_speed * dt), turn by dyaw; speed = step length / dt.

    Returns:
        dict of (n,) float64: x, y, heading, speed, a_long, a_lat.
    """
    x, y, h, v0, dx, dy, dyaw = (np.asarray(a, np.float64) for a in (x, y, heading, speed, dx, dy, dyaw))
    d = np.hypot(dx, dy)
    shrink = np.where(d > max_speed * dt, max_speed * dt / np.maximum(d, 1e-30), 1.0)
    dx, dy, d = dx * shrink, dy * shrink, d * shrink
    v1 = d / dt
    nx = x + np.cos(h) * dx - np.sin(h) * dy
    ny = y + np.sin(h) * dx + np.cos(h) * dy
    nh = np.angle(np.exp(1j * (h + dyaw)))
    return {"x": nx, "y": ny, "heading": nh, "speed": v1, "a_long": (v1 - v0) / dt, "a_lat": v1 * dyaw / dt}
