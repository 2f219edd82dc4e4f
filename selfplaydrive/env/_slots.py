"""Per-slot view of one `VecEnv.step`, shared by the adapters (no simulation logic here).

Slot conventions (docs/interfaces/gymnasium.md): a slot that did not act this step (empty,
or its agent ended earlier in the world's episode) gets reward 0, terminated = truncated =
False; a slot that does not act next step gets an all-zero observation, so stale rows of the
native buffers never leak into a learner.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np


@dataclass
class SlotStep:
    """Copies of one step's results, one row per agent slot (N = num_worlds * agents).

    Attributes:
        obs: (N, obs_dim) float32 next observations; zeros where `active` is False.
        reward: (N,) float32, zero where `acted` is False.
        terminated: (N,) bool, the slot's agent ended this step by an event.
        truncated: (N,) bool, the slot's agent reached the time limit this step.
        final_obs: (N, obs_dim) float32 last observation of agents that ended (else zeros).
        acted: (N,) bool, the slot held an agent that acted this step.
        active: (N,) bool, the slot holds an agent that acts at the next step.
        world_reset: (N,) bool, the slot's world was resampled at the end of this step.
    """

    obs: np.ndarray
    reward: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    final_obs: np.ndarray
    acted: np.ndarray
    active: np.ndarray
    world_reset: np.ndarray


def observe(env: Any) -> np.ndarray:
    """Copy of the observations with rows of inactive slots zeroed."""
    return np.where(env.masks[:, None], env.observations, np.float32(0.0)).astype(np.float32)


def collect(env: Any) -> SlotStep:
    """Read the results of the `env.step` just taken (copies, safe to keep)."""
    acted = env.reward_mask.copy()
    term = env.terminations & acted
    trunc = env.truncations & acted
    ended = term | trunc
    final = np.where(ended[:, None], env.final_observations, np.float32(0.0)).astype(np.float32)
    reset_w = np.asarray(env.state.step) == 0
    return SlotStep(
        obs=observe(env),
        reward=np.where(acted, env.rewards, np.float32(0.0)).astype(np.float32),
        terminated=term,
        truncated=trunc,
        final_obs=final,
        acted=acted,
        active=env.masks.copy(),
        world_reset=np.repeat(reset_w, env.agents_per_world),
    )


def seed_stream(seed: int | None, rng: np.random.Generator | None) -> tuple[int, np.random.Generator]:
    """Seed for the next `VecEnv.reset` and the adapter's generator.

    `VecEnv.reset(None)` replays the env's last seed; the adapters instead draw a fresh seed
    from their own generator, so unseeded resets give new episodes while `reset(seed=s)` stays
    reproducible.
    """
    if seed is not None:
        rng = np.random.default_rng(seed)
    elif rng is None:
        rng = np.random.default_rng()
    return int(rng.integers(0, 2**62)), rng


def check_open(closed: bool, where: str) -> None:
    """Refuse to use an adapter after `close()`.

    Raises:
        RuntimeError: When `closed` is set, naming the call `where` that was refused.
    """
    if closed:
        raise RuntimeError(f"{where}: the env is closed (close() was called); create a new one")


def check_action(space: gym.Space, action: object, name: str) -> np.ndarray:
    """One agent's action as a (2,) array ready for the native action buffer.

    The adapters copy single actions into a table of the native dtype, and NumPy's cast would
    silently truncate 6.9 to index 6 and turn NaN into index -2**63, so the action is checked
    against the space first, as the native `VecEnv.step` checks whole batches.

    Args:
        space: The native action space (MultiDiscrete indices or a Box).
        action: The agent's action (array-like of 2 values).
        name: How the error names the action (e.g. ``"action"``, ``"actions['agent_3']"``).

    Returns:
        (2,) int64 indices (MultiDiscrete) or float32 values (Box).

    Raises:
        ValueError: Wrong shape or dtype, a non-finite value or a value outside the space.
    """
    a = np.asarray(action)
    # (2,) for the bicycle models; a physics model may declare other action columns (physics=delta: 3)
    dim = (
        len(space.nvec) if isinstance(space, gym.spaces.MultiDiscrete) else int(np.prod(space.shape or (2,)))
    )
    if a.shape != (dim,):
        raise ValueError(f"{name}: expected shape ({dim},), got shape {a.shape} ({action!r})")
    if isinstance(space, gym.spaces.MultiDiscrete):
        return _check_indices(a, np.asarray(space.nvec), name)
    if isinstance(space, gym.spaces.Box):
        return _check_box(a, space, name)
    raise TypeError(f"{name}: unsupported action space {space!r}; expected MultiDiscrete or Box")


def _check_indices(a: np.ndarray, nvec: np.ndarray, name: str) -> np.ndarray:
    expected = f"integer indices in [0, {nvec[0]}) x [0, {nvec[1]}) (MultiDiscrete {nvec.tolist()})"
    if a.dtype.kind not in "iu":
        # floats are refused, not rounded: 6.9 is no index, and NaN would cast to -2**63
        raise ValueError(f"{name} = {a}: expected {expected} of an integer dtype, got dtype {a.dtype}")
    bad = (a < 0) | (a >= nvec)
    if bad.any():
        j = int(np.argmax(bad))
        raise ValueError(f"{name}[{j}] = {a[j]}: expected an integer in [0, {nvec[j]}) ({expected})")
    return a.astype(np.int64)


def _check_box(a: np.ndarray, space: gym.spaces.Box, name: str) -> np.ndarray:
    low, high = np.asarray(space.low), np.asarray(space.high)
    if a.dtype.kind != "f":
        raise ValueError(f"{name} = {a}: expected a float array (Box {low} .. {high}), got dtype {a.dtype}")
    # the float32 bounds get the native check's relative slack, so a float64 copy of a bound passes
    slack_lo, slack_hi = 1e-6 * np.abs(low), 1e-6 * np.abs(high)
    bad = ~np.isfinite(a) | (a < low - slack_lo) | (a > high + slack_hi)
    if bad.any():
        j = int(np.argmax(bad))
        raise ValueError(f"{name}[{j}] = {a[j]}: expected a finite number in [{low[j]}, {high[j]}]")
    return a.astype(np.float32)
