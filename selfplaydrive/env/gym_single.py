"""`SingleAgentEnv`: one ego vehicle of a one-world `VecEnv` as a `gymnasium.Env`; the other
vehicles are driven by the rule-based driver, a given policy, or stand still.

See docs/interfaces/gymnasium.md. The ego is the first filled agent slot of the world. Its
episode ends when it terminates (collision / road-edge event above the threshold) or when the
world's time runs out (truncation); the observation returned then is its final observation.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

from selfplaydrive.drivers.static import static_actions
from selfplaydrive.env._slots import check_action, check_open, observe, seed_stream

OthersPolicy = Callable[[np.ndarray], np.ndarray]
MAX_EMPTY_RESETS = 16


class SingleAgentEnv(gym.Env):
    """Single-agent gymnasium view of a one-world `selfplaydrive.sim.VecEnv`.

    Args:
        env: The native env; it must have `num_worlds == 1`.
        others: How the other vehicles act: "rule_based" (`RuleBasedDriver`), "static"
            (full braking, zero steering: they stop and stay), or a callable mapping the
            (A - 1, obs_dim) observations of the other slots (zeros for empty slots) to
            (A - 1, 2) actions in the env's action space.
        render_mode: Must be None: the env draws nothing (accepted so `gymnasium.make` can
            pass it).

    Raises:
        ValueError: On a multi-world env, an unknown `others` or a render mode.
    """

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(self, env: Any, others: str | OthersPolicy = "rule_based", render_mode: None = None) -> None:
        if env.num_worlds != 1:
            raise ValueError(
                f"SingleAgentEnv: expected a VecEnv with num_worlds=1, got num_worlds={env.num_worlds}"
            )
        if not (callable(others) or others in ("rule_based", "static")):
            raise ValueError(f"others: expected 'rule_based', 'static' or a callable, got {others!r}")
        if render_mode is not None:
            raise ValueError(f"render_mode: SingleAgentEnv draws nothing, expected None, got {render_mode!r}")
        self.render_mode = None
        self.env = env
        self.others = others
        self.observation_space = env.observation_space
        self.action_space = env.action_space
        self.ego = 0
        self._driver: Any = None
        if others == "rule_based":
            from selfplaydrive.drivers.rule_based import RuleBasedDriver

            self._driver = RuleBasedDriver(env)
        self._seeds: np.random.Generator | None = None
        self._done = True
        self._closed = False

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """New episode; the same seed gives the same episode (and the same rollout)."""
        super().reset(seed=seed)
        for _ in range(MAX_EMPTY_RESETS):
            s, self._seeds = seed_stream(seed, self._seeds)
            seed = None
            self.env.reset(s)
            filled = np.flatnonzero(self.env.masks)
            if len(filled):
                break
        else:
            raise RuntimeError(f"SingleAgentEnv: the spawner gave no agent in {MAX_EMPTY_RESETS} episodes")
        self.ego = int(filled[0])
        if self._driver is not None:
            self._driver.reset()
        self._done = False
        return observe(self.env)[self.ego], {"ego_slot": self.ego}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Apply the ego's action (2,); the others act by `others`.

        Returns:
            observation (obs_dim,) float32, reward, terminated, truncated, info with
            `reward_terms` (M,) float32 (columns `VecEnv.term_names`, the paper's 8 by default)
            and `events` (bit mask).

        Raises:
            ValueError: An action outside the action space (a float or NaN index included).
            RuntimeError: After `close()`, or when the episode has ended (call `reset()`).
        """
        check_open(self._closed, "SingleAgentEnv.step")
        ego_action = check_action(self.action_space, action, "action")
        if self._done:
            raise RuntimeError("SingleAgentEnv.step: the episode has ended; call reset() first")
        acts = self._other_actions()
        acts[self.ego] = ego_action
        env, e = self.env, self.ego
        env.step(acts)
        term, trunc = bool(env.terminations[e]), bool(env.truncations[e])
        self._done = term or trunc
        obs = (env.final_observations[e] if self._done else env.observations[e]).astype(np.float32)
        info = {"reward_terms": env.reward_terms[e].copy(), "events": int(env.state.events[e])}
        return obs, float(env.rewards[e]), term, trunc, info

    def close(self) -> None:
        """Mark the env closed: later `step` calls raise (the native env holds only buffers)."""
        self._closed = True

    def _other_actions(self) -> np.ndarray:
        env = self.env
        if self._driver is not None:
            return self._driver.act()
        table = env.action_table
        if callable(self.others):
            rows = np.arange(env.num_agents) != self.ego
            out = np.asarray(self.others(observe(env)[rows]))
            d = int(table.dim)  # 2, or the physics model's own action columns
            if out.shape != (env.num_agents - 1, d):
                raise ValueError(
                    f"others policy: expected actions of shape ({env.num_agents - 1}, {d}), got {out.shape}"
                )
            acts = np.zeros((env.num_agents, d), dtype=out.dtype)
            acts[rows] = out
            return acts
        return static_actions(table, env.num_agents)
