"""`check_physics`: check a physics component against the contract of `sd_physics_fn`
(selfplaydrive_abi.h; docs/components.md "Write a physics model"; paper section 2.6).

The model steps the physics stage alone (`World.physics_stage`) of a small env on the
bundled map, from states reached by driving it with random valid actions, and the checker
compares every buffer before and after:

- outputs only: every buffer other than the model's outputs (x, y, heading, hcos, hsin,
  speed, px, py, pheading, a_long, a_lat, its own phys_state, and the step's events / dist) is
  unchanged, byte for byte; inactive slots keep their pose and speed;
- shapes: phys_state is (N, state_dim), the action buffers (N, action columns);
- finite outputs, speed in [0, max_speed], heading in (-pi, pi], hcos / hsin the cosine / sine
  of the heading, no displacement longer than max_speed * dt;
- determinism: the same outputs, bit for bit, at 1 and 2 threads and when run twice.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

# what a physics model (and the step around it) may write (selfplaydrive_abi.h)
OUTPUTS = frozenset("x y heading hcos hsin speed px py pheading a_long a_lat phys_state events dist".split())
POSE = ("x", "y", "heading", "hcos", "hsin", "speed")


class PhysicsCheckError(AssertionError):
    """A physics model broke its contract; the message names the check, buffer, slot and value."""


def check_physics(
    model: Any,
    map: str = "default",
    num_worlds: int = 4,
    rounds: int = 12,
    seed: int = 0,
    actions: Any = None,
) -> dict[str, object]:
    """Check `model` against the physics-component contract; raise on the first violation.

    Args:
        model: A physics model (`selfplaydrive.physics.PhysicsModel`, e.g. a `KernelPhysics`).
        map: Map spec of the env (`load_map`).
        num_worlds: Worlds of the env.
        rounds: States checked (the env is driven one full step with random actions between them).
        seed: Seed of the env and of the random actions.
        actions: Action table to check with (default: the model's own, else the env's).

    Returns:
        A summary: model name, rounds, agent-steps checked, largest speed and displacement seen.

    Raises:
        PhysicsCheckError: The model wrote outside its outputs, wrote non-finite or out-of-range
            values, or gave different results at 1 and 2 threads or on a second run.
    """
    from selfplaydrive.builder import make_env

    env = make_env(map, num_worlds=num_worlds, seed=seed, physics=model, actions=actions)
    name = getattr(model, "name", type(model).__name__)
    b = env.buffers
    N = env.num_agents
    table = env.action_table
    _require(
        b["phys_state"].shape == (N, int(model.state_dim)),
        name,
        f"phys_state: shape {b['phys_state'].shape}, expected ({N}, {model.state_dim})",
    )
    for key in ("act_i", "act_f"):
        _require(
            b[key].shape == (N, table.dim), name, f"{key}: shape {b[key].shape}, expected ({N}, {table.dim})"
        )
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    dt = float(env.params.dt)
    max_speed = float(model.max_speed)
    checked, top_speed, top_move = 0, 0.0, 0.0
    for _ in range(rounds):
        acts = _random_actions(table, N, rng)
        a = table.validate(acts, N)
        np.copyto(b["act_i" if table.discrete else "act_f"], a)
        before = {k: v.copy() for k, v in b.items()}
        results = []
        for threads in (1, 2, 1):
            for k, v in before.items():
                np.copyto(b[k], v)
            if getattr(model, "external", False):
                env._step_external_physics(b["act_i" if table.discrete else "act_f"])
            env._world.physics_stage(threads)
            results.append({k: v.copy() for k, v in b.items()})
        for k in OUTPUTS:
            for r, label in ((results[1], "2 threads"), (results[2], "a second run")):
                if not np.array_equal(results[0][k], r[k], equal_nan=True):
                    i = int(np.flatnonzero((results[0][k] != r[k]).reshape(len(r[k]), -1).any(axis=1))[0])
                    raise PhysicsCheckError(
                        f"physics {name!r}: not deterministic: {k}[{i}] = {results[0][k][i]} at 1 thread, "
                        f"{r[k][i]} with {label}"
                    )
        after = results[0]
        for k, v in before.items():
            if k not in OUTPUTS and not np.array_equal(v, after[k], equal_nan=True):
                raise PhysicsCheckError(
                    f"physics {name!r}: wrote buffer {k!r}, which is not one of its outputs {sorted(OUTPUTS)}"
                )
        active = before["active"].astype(bool)
        for k in POSE:
            moved = ~active & (before[k] != after[k])
            if moved.any():
                i = int(np.argmax(moved))
                raise PhysicsCheckError(
                    f"physics {name!r}: changed {k}[{i}] of an inactive slot "
                    f"({before[k][i]} -> {after[k][i]})"
                )
        _check_values(name, before, after, active, dt, max_speed)
        if active.any():
            top_speed = max(top_speed, float(after["speed"][active].max()))
            move = np.hypot(after["x"] - before["x"], after["y"] - before["y"])[active]
            top_move = max(top_move, float(move.max()))
        checked += int(active.sum())
        for k, v in before.items():  # leave the env as the stage found it, then drive it on
            np.copyto(b[k], v)
        env.step(acts)
    return {
        "model": name,
        "rounds": rounds,
        "agent_steps": checked,
        "max_speed_seen": top_speed,
        "max_step_length_seen": top_move,
    }


def _check_values(
    name: str,
    before: dict[str, np.ndarray],
    after: dict[str, np.ndarray],
    active: np.ndarray,
    dt: float,
    vmax: float,
) -> None:
    for k in (*POSE, "a_long", "a_lat", "phys_state"):
        v = after[k][active]
        if not np.all(np.isfinite(v)):
            i = int(
                np.flatnonzero(active)[np.flatnonzero(~np.isfinite(v).reshape(len(v), -1).all(axis=1))[0]]
            )
            raise PhysicsCheckError(f"physics {name!r}: {k}[{i}] = {after[k][i]} is not finite")
    idx = np.flatnonzero(active)
    v = after["speed"][idx]
    bad = (v < 0) | (v > vmax * (1 + 1e-6))
    if bad.any():
        i = int(idx[np.argmax(bad)])
        raise PhysicsCheckError(
            f"physics {name!r}: speed[{i}] = {after['speed'][i]}, expected a value in [0, {vmax}] m/s"
        )
    h = after["heading"][idx]
    bad = (h <= -math.pi - 1e-6) | (h > math.pi + 1e-6)
    if bad.any():
        i = int(idx[np.argmax(bad)])
        raise PhysicsCheckError(
            f"physics {name!r}: heading[{i}] = {after['heading'][i]}, expected a value in (-pi, pi]"
        )
    for k, f in (("hcos", np.cos), ("hsin", np.sin)):
        err = np.abs(after[k][idx] - f(after["heading"][idx].astype(np.float64)))
        if (err > 1e-5).any():
            i = int(idx[np.argmax(err)])
            raise PhysicsCheckError(
                f"physics {name!r}: {k}[{i}] = {after[k][i]}, expected {f.__name__}(heading) = "
                f"{f(float(after['heading'][i]))}"
            )
    step = np.hypot(after["x"][idx] - before["x"][idx], after["y"][idx] - before["y"][idx])
    bad = step > vmax * dt * (1 + 1e-4) + 1e-4
    if bad.any():
        i = int(idx[np.argmax(bad)])
        raise PhysicsCheckError(
            f"physics {name!r}: slot {i} moved {float(step[np.argmax(bad)]):.4f} m in one step, more than "
            f"max_speed * dt = {vmax * dt:.4f} m"
        )


def _random_actions(table: Any, n: int, rng: np.random.Generator) -> np.ndarray:
    if table.discrete:
        return np.stack([rng.integers(0, len(table.accel), n), rng.integers(0, len(table.steer), n)], axis=1)
    lo, hi = table.low.astype(np.float64), table.high.astype(np.float64)
    return (lo + (hi - lo) * rng.random((n, table.dim))).astype(np.float32)


def _require(ok: bool, name: str, what: str) -> None:
    if not ok:
        raise PhysicsCheckError(f"physics {name!r}: {what}")
