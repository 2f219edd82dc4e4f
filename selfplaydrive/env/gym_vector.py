"""`GymVectorEnv`: the native `VecEnv` as a `gymnasium.vector.VectorEnv`, one sub-env per agent
slot (N = num_worlds * agents per world). See docs/interfaces/gymnasium.md.

Autoreset is `AutoresetMode.SAME_STEP`, as in the native env: when a world ends (time limit,
or all its agents ended) it is resampled inside `step`; the returned observations of its slots
are the new episode's first ones and the last ones are in `infos["final_obs"]` (rows where
`infos["_final_obs"]` is set). Slots that hold no acting agent get reward 0, terminated =
truncated = False and an all-zero observation; `infos["active"]` says which slots act at the
next step and `infos["acted"]` which acted in this one.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from selfplaydrive.env._slots import collect, observe, seed_stream


class GymVectorEnv(gym.vector.VectorEnv):
    """Gymnasium vector view of a `selfplaydrive.sim.VecEnv`.

    Args:
        env: The native env (already constructed; its buffers are read, never copied in place).
    """

    metadata: dict[str, Any] = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": []}

    def __init__(self, env) -> None:
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

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict]:
        """Step every world with (N, 2) actions (rows of inactive slots are ignored).

        Returns:
            observations (N, obs_dim), rewards (N,) float32, terminations (N,), truncations
            (N,), infos: `active`, `acted`, `world_reset` (N,) bool and `final_obs`
            (N, obs_dim) valid where `_final_obs`.
        """
        self.env.step(np.asarray(actions))
        r = collect(self.env)
        ended = r.terminated | r.truncated
        every = np.ones(self.num_envs, bool)
        infos = {
            "active": r.active,
            "_active": every,
            "acted": r.acted,
            "_acted": every,
            "world_reset": r.world_reset,
            "_world_reset": every,
            "final_obs": r.final_obs,
            "_final_obs": ended,
        }
        return r.obs, r.reward, r.terminated, r.truncated, infos

    def pop_episode_stats(self) -> list[dict[str, object]]:
        """Per-world episode statistics of the native env (see `VecEnv.pop_episode_stats`)."""
        return self.env.pop_episode_stats()
