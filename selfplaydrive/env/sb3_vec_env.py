"""`SB3VecEnv`: the native `VecEnv` as a stable-baselines3 `VecEnv`, one SB3 env per agent slot.
See docs/interfaces/sb3.md for why inactive slots are reported the way they are.

Per slot and step:
- an acting agent: its reward, done = terminated or truncated; when done,
  `info["terminal_observation"]` is its final observation and `info["TimeLimit.truncated"]`
  is True for a time-limit end (so SB3 bootstraps it) and False for an event termination;
- an inactive slot (empty, or its agent ended earlier in the world's episode): reward 0, an
  all-zero observation, `info["inactive"] = True`, done = False, except at the step its world is
  resampled, where done = True with a zero `terminal_observation` and
  `TimeLimit.truncated = False`. This cuts the slot's trajectory there, so the zero-reward
  stretch never bootstraps from, nor leaks into, the value of the next agent in that slot.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from selfplaydrive._optional import requires_extra
from selfplaydrive.env._slots import check_open, collect, observe, seed_stream

with requires_extra("sb3"):
    from stable_baselines3.common.vec_env.base_vec_env import VecEnv as SB3BaseVecEnv


class SB3VecEnv(SB3BaseVecEnv):
    """stable-baselines3 view of a `selfplaydrive.sim.VecEnv` (num_envs = agent slots).

    Args:
        env: The native env.
        seed: Seed of the first `reset` (later resets continue the adapter's seed stream;
            `seed()` before `reset()` restarts it).
    """

    render_mode = None

    def __init__(self, env: Any, seed: int | None = 0) -> None:
        self.env = env
        self.closed = False
        self._rng: np.random.Generator | None = None
        self._first_seed = seed
        self._actions: np.ndarray | None = None
        super().__init__(env.num_agents, env.observation_space, env.action_space)

    def reset(self) -> np.ndarray:
        """Start new episodes in every world; (N, obs_dim) float32 observations."""
        seed = self._seeds[0] if self._seeds[0] is not None else self._first_seed
        self._first_seed = None
        s, self._rng = seed_stream(seed, self._rng)
        self.env.reset(s)
        self._reset_seeds()
        self.reset_infos = [{"inactive": not m} for m in self.env.masks]
        return observe(self.env)

    def step_async(self, actions: np.ndarray) -> None:
        """Keep (N, 2) actions for `step_wait` (checked there by the native env).

        Raises:
            RuntimeError: After `close()`.
            ValueError: Actions that do not hold N rows of 2 values.
        """
        check_open(self.closed, "SB3VecEnv.step_async")
        a = np.asarray(actions)
        d = int(self.env.action_table.dim)  # 2, or the physics model's own action columns
        if a.size != self.num_envs * d:
            raise ValueError(f"actions: expected shape ({self.num_envs}, {d}), got shape {a.shape}")
        self._actions = a.reshape(self.num_envs, d)

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        """Step every world (see the module docstring for the per-slot values)."""
        check_open(self.closed, "SB3VecEnv.step_wait")
        if self._actions is None:
            raise RuntimeError("SB3VecEnv.step_wait: call step_async(actions) first")
        self.env.step(self._actions)
        self._actions = None
        r = collect(self.env)
        ended = r.terminated | r.truncated
        idle_cut = ~r.acted & r.world_reset
        dones = ended | idle_cut
        infos: list[dict[str, Any]] = []
        for i in range(self.num_envs):
            info: dict[str, Any] = {"inactive": not r.acted[i]}
            if dones[i]:
                info["terminal_observation"] = r.final_obs[i]
                info["TimeLimit.truncated"] = bool(r.truncated[i] and not r.terminated[i])
            infos.append(info)
        return r.obs, r.reward, dones, infos

    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        """Seed of the next `reset` (all slots share the native env's seed)."""
        self._seeds = [seed] * self.num_envs
        return self._seeds

    def close(self) -> None:
        """Mark the env closed (the native env holds only NumPy buffers): later steps raise."""
        self.closed = True
        self._actions = None

    def get_attr(self, attr_name: str, indices=None) -> list[Any]:
        return [getattr(self, attr_name)] * len(list(self._get_indices(indices)))

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        setattr(self, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list[Any]:
        out = getattr(self.env, method_name)(*method_args, **method_kwargs)
        return [out] * len(list(self._get_indices(indices)))

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        return [False] * len(list(self._get_indices(indices)))
