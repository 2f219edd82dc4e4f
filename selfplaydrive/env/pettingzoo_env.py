"""`DrivingParallelEnv`: one world of a `VecEnv` as a PettingZoo `ParallelEnv`; its agents are
the world's vehicles, named "agent_<slot>". See docs/interfaces/pettingzoo.md.

An agent that terminates (collision / road-edge event above the threshold) leaves `agents`;
when the world's time runs out every remaining agent is truncated and `agents` becomes empty.
The native env's autoreset of the world is hidden: after the last agent leaves, the episode is
over until `reset()`.
"""

from __future__ import annotations

import functools
from typing import Any

import gymnasium as gym
import numpy as np
from pettingzoo import ParallelEnv

from selfplaydrive.drivers.static import static_actions
from selfplaydrive.env._slots import observe, seed_stream


class DrivingParallelEnv(ParallelEnv):
    """PettingZoo parallel view of a one-world `selfplaydrive.sim.VecEnv`.

    Args:
        env: The native env; it must have `num_worlds == 1`. `possible_agents` are all its
            agent slots; each episode's `agents` are the slots its scenario fills.

    Raises:
        ValueError: On a multi-world env.
    """

    metadata: dict[str, Any] = {
        "name": "selfplaydrive_parallel_v0",
        "render_modes": [],
        "is_parallelizable": True,
    }

    def __init__(self, env) -> None:
        if env.num_worlds != 1:
            raise ValueError(
                f"DrivingParallelEnv: expected a VecEnv with num_worlds=1, got num_worlds={env.num_worlds}"
            )
        self.env = env
        self.possible_agents = [f"agent_{i}" for i in range(env.num_agents)]
        self._slot = {name: i for i, name in enumerate(self.possible_agents)}
        self.agents: list[str] = []
        self._rng: np.random.Generator | None = None

    @functools.cache  # noqa: B019 - spaces must be the same object per agent
    def observation_space(self, agent: str) -> gym.spaces.Box:
        self._check_name(agent)
        return self.env.observation_space

    @functools.cache  # noqa: B019
    def action_space(self, agent: str) -> gym.spaces.Space:
        self._check_name(agent)
        space = self.env.action_space
        return type(space)(space.nvec) if hasattr(space, "nvec") else type(space)(space.low, space.high)

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, dict]]:
        """New episode; the same seed gives the same episode."""
        s, self._rng = seed_stream(seed, self._rng)
        self.env.reset(s)
        obs = observe(self.env)
        self.agents = [self.possible_agents[i] for i in np.flatnonzero(self.env.masks)]
        return {a: obs[self._slot[a]] for a in self.agents}, {a: {} for a in self.agents}

    def step(self, actions: dict[str, np.ndarray]) -> tuple[dict, dict, dict, dict, dict]:
        """Step the world; agents missing from `actions` brake fully with zero steering.

        Raises:
            ValueError: An action for an unknown agent or one not in `agents`.
        """
        live = set(self.agents)
        for name in actions:
            if name not in live:
                raise ValueError(f"actions: agent {name!r} is not in env.agents ({sorted(live)[:4]}...)")
        if not self.agents:
            return {}, {}, {}, {}, {}
        env = self.env
        acts = static_actions(env.action_table, env.num_agents)
        for name, a in actions.items():
            acts[self._slot[name]] = np.asarray(a).reshape(2)
        env.step(acts)
        term, trunc = env.terminations, env.truncations
        ended = term | trunc
        obs_now = observe(env)
        obs, rew, te, tr, info = {}, {}, {}, {}, {}
        for name in self.agents:
            i = self._slot[name]
            obs[name] = env.final_observations[i].astype(np.float32) if ended[i] else obs_now[i]
            rew[name] = float(env.rewards[i])
            te[name] = bool(term[i])
            tr[name] = bool(trunc[i])
            info[name] = {"events": int(env.state.events[i])}
        self.agents = [a for a in self.agents if not (te[a] or tr[a])]
        if tr and any(tr.values()):
            # time limit: the episode ends for everyone (the native world was resampled)
            self.agents = []
        return obs, rew, te, tr, info

    def _check_name(self, agent: str) -> None:
        if agent not in self._slot:
            raise ValueError(f"agent: expected one of agent_0..agent_{len(self._slot) - 1}, got {agent!r}")
