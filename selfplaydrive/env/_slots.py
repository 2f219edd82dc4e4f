"""Per-slot view of one `VecEnv.step`, shared by the adapters (no simulation logic here).

Slot conventions (docs/interfaces/gymnasium.md): a slot that did not act this step (empty,
or its agent ended earlier in the world's episode) gets reward 0, terminated = truncated =
False; a slot that does not act next step gets an all-zero observation, so stale rows of the
native buffers never leak into a learner.
"""

from __future__ import annotations

from dataclasses import dataclass

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


def observe(env) -> np.ndarray:
    """Copy of the observations with rows of inactive slots zeroed."""
    return np.where(env.masks[:, None], env.observations, np.float32(0.0)).astype(np.float32)


def collect(env) -> SlotStep:
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
