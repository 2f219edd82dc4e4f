"""`GymVectorEnv`: the native `VecEnv` as a `gymnasium.vector.VectorEnv`, one sub-env per agent
slot (N = num_worlds * agents per world). See docs/interfaces/gymnasium.md.

Autoreset is `AutoresetMode.SAME_STEP`, as in the native env: when a world ends (time limit,
or all its agents ended) it is resampled inside `step`; the returned observations of its slots
are the new episode's first ones. The infos of a step in which some slot's agent ended follow
gymnasium's `SyncVectorEnv` in that mode: `infos["final_obs"]` is an (N,) object array holding
the last observation of each ended slot (None elsewhere), `infos["final_info"]` a dict of that
slot's step info (`events`, `reward_terms`, each with its `_key` mask), and `_final_obs` /
`_final_info` mark the ended slots; in a step where nothing ended the four keys are absent.
Slots that hold no acting agent get reward 0, terminated = truncated = False and an all-zero
observation; `infos["active"]` says which slots act at the next step and `infos["acted"]`
which acted in this one.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from selfplaydrive.env._slots import SlotStep, check_open, collect, observe, seed_stream


class GymVectorEnv(gym.vector.VectorEnv):
    """Gymnasium vector view of a `selfplaydrive.sim.VecEnv`.

    Args:
        env: The native env (already constructed; its buffers are read, never copied in place).
        render_mode: Must be None: the env draws nothing (accepted so `gymnasium.make_vec` can
            pass it).

    Raises:
        ValueError: On a render mode.
    """

    metadata: dict[str, Any] = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": []}

    def __init__(self, env: Any, render_mode: None = None) -> None:
        if render_mode is not None:
            raise ValueError(f"render_mode: GymVectorEnv draws nothing, expected None, got {render_mode!r}")
        self.render_mode = None
        self.env = env
        self.num_envs = env.num_agents
        self.single_observation_space = env.observation_space
        self.single_action_space = env.action_space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._rng: np.random.Generator | None = None

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start new episodes in every world.

        Args:
            seed: Same seed, same episodes; None draws the next seed from the adapter's stream.
            options: Unused (accepted for API compatibility).

        Returns:
            (N, obs_dim) float32 observations (zeros for empty slots) and infos with `active`.
        """
        s, self._rng = seed_stream(seed, self._rng)
        self.env.reset(s)
        active = self.env.masks.copy()
        return observe(self.env), {"active": active, "_active": np.ones(self.num_envs, bool)}

    def step(
        self, actions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Step every world with (N, 2) actions (rows of inactive slots are ignored).

        Returns:
            observations (N, obs_dim), rewards (N,) float32, terminations (N,), truncations
            (N,), infos: `active`, `acted`, `world_reset` (N,) bool; when a slot's agent ended,
            also `final_obs` and `final_info` with their masks (see the module docstring).

        Raises:
            ValueError: Actions of the wrong shape or dtype, or out of range (native check).
            RuntimeError: After `close()`.
        """
        check_open(self.closed, "GymVectorEnv.step")
        self.env.step(np.asarray(actions))
        r = collect(self.env)
        every = np.ones(self.num_envs, bool)
        infos: dict[str, Any] = {
            "active": r.active,
            "_active": every,
            "acted": r.acted,
            "_acted": every,
            "world_reset": r.world_reset,
            "_world_reset": every,
        }
        ended = r.terminated | r.truncated
        if ended.any():
            infos.update(self._final_infos(r, ended))
        return r.obs, r.reward, r.terminated, r.truncated, infos

    def _final_infos(self, r: SlotStep, ended: np.ndarray) -> dict[str, Any]:
        """`final_obs` / `final_info` of the ended slots, laid out as gymnasium's
        `SyncVectorEnv._add_info` lays them out (object array of observations; per-key arrays
        with `_key` masks), so code written for gymnasium's same-step envs reads them as is."""
        final_obs = np.full(self.num_envs, None, dtype=object)
        for i in np.flatnonzero(ended):
            final_obs[i] = r.final_obs[i]
        events = np.where(ended, np.asarray(self.env.state.events, dtype=np.int64), 0)
        terms = np.where(ended[:, None], self.env.reward_terms, np.float32(0.0)).astype(np.float32)
        final_info = {
            "events": events,
            "_events": ended.copy(),
            "reward_terms": terms,
            "_reward_terms": ended.copy(),
        }
        return {
            "final_obs": final_obs,
            "_final_obs": ended,
            "final_info": final_info,
            "_final_info": ended.copy(),
        }

    def close_extras(self, **kwargs: Any) -> None:
        """Nothing to release (the native env holds only NumPy buffers); `close()` sets
        `closed`, after which `step` raises."""

    def pop_episode_stats(self) -> list[dict[str, object]]:
        """Per-world episode statistics of the native env (see `VecEnv.pop_episode_stats`)."""
        return self.env.pop_episode_stats()
