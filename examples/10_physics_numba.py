"""Example 10: a physics model written outside the package, as a numba cfunc (needs the `numba`
extra): a kinematic unicycle with quadratic drag.

The cfunc has the C signature of every physics component (`sd_physics_fn` in
selfplaydrive_abi.h; `selfplaydrive.physics.numba_abi.SIGNATURE`), so the step calls it through
a function pointer once per world inside its parallel loop, without the GIL, like the paper's
bicycle: no build step, no Python per step. It reads the actions and the state through the
header's field offsets and writes only the vehicle state a model owns (x, y, heading, hcos, hsin,
speed, a_long, a_lat of the active slots; the step has set px, py, pheading and zeroed a_long,
a_lat before the call).

The model: the actions are acceleration a [m/s^2] and yaw rate omega [rad/s] (its own discrete
tables, `ACCEL`, `YAW_RATE_DEG`), both times the vehicle's hidden gains (section 2.6);
dv/dt = a - drag * v^2, v clamped to [0, max_speed]; the heading turns by omega dt and the car
moves v dt along the new heading. No slip, no friction limit: an ablation against the bicycle.

Select it in one Hydra override:

    selfplaydrive train physics=custom physics.model.target=examples/10_physics_numba.py:unicycle

Run: python examples/10_physics_numba.py [--tiny]   (pip install 'selfplaydrive[numba]')
"""

from __future__ import annotations

import math
import os
import sys

import numpy as np
from numba import cfunc

from selfplaydrive import make_env
from selfplaydrive.physics import KernelPhysics
from selfplaydrive.physics.numba_abi import (
    PARAMS,
    SIGNATURE,
    SIM,
    f32_ptr,
    float_field,
    i32_ptr,
    int_field,
    u8_ptr,
)
from selfplaydrive.sim.actions import DiscreteActions
from selfplaydrive.testing.check_physics import check_physics

ACCEL = (-4.0, -2.0, -1.0, 0.0, 1.0, 2.0, 3.0)  # [m/s^2]
YAW_RATE_DEG = (-40.0, -20.0, -10.0, -4.0, 0.0, 4.0, 10.0, 20.0, 40.0)  # [deg/s]
H_ACCEL_GAIN, H_STEER_GAIN = 1, 2  # columns of the hidden parameters (selfplaydrive_abi.h SD_H_*)


@cfunc(SIGNATURE)
def unicycle_step(sim, prm, args, w, state):  # type: ignore[no-untyped-def]
    """Unicycle with drag; args: max_speed [m/s], drag [1/m]."""
    A = int_field(sim, SIM.A)
    D = int_field(sim, SIM.act_dim)
    dt = float_field(prm, PARAMS.dt)
    accel_table, yaw_table = f32_ptr(prm, PARAMS.accel_table), f32_ptr(prm, PARAMS.steer_table)
    act = i32_ptr(sim, SIM.act_i)
    active, hidden = u8_ptr(sim, SIM.active), f32_ptr(sim, SIM.hidden)
    x, y, heading = f32_ptr(sim, SIM.x), f32_ptr(sim, SIM.y), f32_ptr(sim, SIM.heading)
    hcos, hsin, speed = f32_ptr(sim, SIM.hcos), f32_ptr(sim, SIM.hsin), f32_ptr(sim, SIM.speed)
    a_long, a_lat = f32_ptr(sim, SIM.a_long), f32_ptr(sim, SIM.a_lat)
    vmax, drag = args[0], args[1]
    for a in range(A):
        i = w * A + a
        if not active[i]:
            continue
        acc = accel_table[act[D * i]] * hidden[3 * i + H_ACCEL_GAIN]
        omega = yaw_table[act[D * i + 1]] * hidden[3 * i + H_STEER_GAIN]
        v0 = speed[i]
        v1 = min(max(v0 + (acc - drag * v0 * v0) * dt, np.float32(0.0)), vmax)
        th = heading[i] + omega * dt
        if th > math.pi:  # one turn at most: |omega dt| is far below 2 pi
            th -= 2.0 * math.pi
        elif th <= -math.pi:
            th += 2.0 * math.pi
        c, s = math.cos(th), math.sin(th)
        x[i] += v1 * c * dt
        y[i] += v1 * s * dt
        heading[i], hcos[i], hsin[i], speed[i] = th, c, s, v1
        a_long[i] = (v1 - v0) / dt
        a_lat[i] = v1 * omega


def unicycle(max_speed: float = 40.0, drag: float = 0.002) -> KernelPhysics:
    """The cfunc as a physics model with its own discrete action space (Hydra's
    `physics.model.target` names this factory; its arguments are `physics.model` keys)."""
    actions = DiscreteActions(ACCEL, YAW_RATE_DEG).labelled(("accel", "yaw_rate"), ("m/s^2", "rad/s"))
    return KernelPhysics.from_numba(
        "unicycle",
        unicycle_step,
        args=(max_speed, drag),
        actions=actions,
        accepts=("discrete",),
        max_speed=max_speed,
    )


def main(small: bool) -> None:
    model = unicycle()
    print(model.describe())
    report = check_physics(model, rounds=4 if small else 20)
    top = report["max_speed_seen"]
    print(f"check_physics: passed ({report['agent_steps']} agent-steps, top speed {top:.2f} m/s)")
    env = make_env("default", num_worlds=2 if small else 16, physics=model, seed=0)
    env.reset(0)
    rng = np.random.default_rng(0)
    steps, dist = (40 if small else 400), 0.0
    for _ in range(steps):
        # mostly accelerating (accel indices 4-6), gentle turns (yaw-rate indices 2-6)
        env.step(np.stack([rng.integers(4, 7, env.num_agents), rng.integers(2, 7, env.num_agents)], axis=1))
        dist += float(env.buffers["speed"][env.masks].sum()) * env.params.dt
    print(f"unicycle: {env.num_agents} agents drove {dist:.1f} m in {steps} steps")


if __name__ == "__main__":
    main("--tiny" in sys.argv or os.environ.get("SELFPLAYDRIVE_EXAMPLE_TINY") == "1")
