# cython: language_level=3
"""Kinematic unicycle with quadratic drag as a selfplaydrive physics component (the model of
examples/10_physics_numba.py in Cython). Actions: acceleration [m/s^2] and yaw rate [rad/s]
from the model's value tables, times the hidden gains; args: max_speed [m/s], drag [1/m]."""

from libc.math cimport cos, sin, M_PI
from libc.stdint cimport int32_t
from selfplaydrive_abi cimport Sim, Params, H_ACCEL_GAIN, H_STEER_GAIN


cdef void unicycle(Sim* sim, const Params* prm, const float* args, int32_t w, float* state) noexcept nogil:
    cdef int a, i, A = sim.A, D = sim.act_dim
    cdef float acc, omega, v0, v1, dt = prm.dt, vmax = args[0], drag = args[1]
    cdef double th, c, s
    for a in range(A):
        i = w * A + a
        if not sim.active[i]:
            continue
        acc = prm.accel_table[sim.act_i[D * i]] * sim.hidden[3 * i + H_ACCEL_GAIN]
        omega = prm.steer_table[sim.act_i[D * i + 1]] * sim.hidden[3 * i + H_STEER_GAIN]
        v0 = sim.speed[i]
        v1 = v0 + (acc - drag * v0 * v0) * dt
        v1 = 0.0 if v1 < 0.0 else (vmax if v1 > vmax else v1)
        th = sim.heading[i] + omega * dt
        if th > M_PI:  # one turn at most: |omega dt| is far below 2 pi
            th -= 2.0 * M_PI
        elif th <= -M_PI:
            th += 2.0 * M_PI
        c = cos(th)
        s = sin(th)
        sim.x[i] = sim.x[i] + v1 * c * dt
        sim.y[i] = sim.y[i] + v1 * s * dt
        sim.heading[i] = th
        sim.hcos[i] = c
        sim.hsin[i] = s
        sim.speed[i] = v1
        sim.a_long[i] = (v1 - v0) / dt
        sim.a_lat[i] = v1 * omega
