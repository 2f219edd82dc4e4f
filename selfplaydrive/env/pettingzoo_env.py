"""`DrivingParallelEnv`: one world of a `VecEnv` as a PettingZoo `ParallelEnv`; its agents are
the world's vehicles, named "agent_<slot>". See docs/interfaces/pettingzoo.md.

An agent that terminates (collision / road-edge event above the threshold) leaves `agents`;
when the world's time runs out every remaining agent is truncated and `agents` becomes empty.
The native env's autoreset of the world is hidden: after the last agent leaves, the episode is
over until `reset()`. With `render_mode="rgb_array"`, `render()` draws the world top-down with
the episode renderer of `selfplaydrive.render` (docs/rendering.md).
"""

from __future__ import annotations

import functools
from typing import Any

import gymnasium as gym
import numpy as np

from selfplaydrive._optional import requires_extra
from selfplaydrive.drivers.static import static_actions
from selfplaydrive.env._slots import check_action, check_open, observe, seed_stream

with requires_extra("pettingzoo"):
    from pettingzoo import ParallelEnv

RENDER_MODES = ("rgb_array",)


class DrivingParallelEnv(ParallelEnv):
    """PettingZoo parallel view of a one-world `selfplaydrive.sim.VecEnv`.

    Args:
        env: The native env; it must have `num_worlds == 1`. `possible_agents` are all its
            agent slots; each episode's `agents` are the slots its scenario fills.
        render_mode: None, or "rgb_array": `render()` returns a (render_size, render_size, 3)
            uint8 top-down image of the world. Rendering wraps `env.spawner` in a
            `selfplaydrive.render.ScenarioLog` (same samples) so the camera frames each
            episode's spawn region.
        render_size: Edge of the rendered image [px], 64 to 8192.

    Raises:
        ValueError: On a multi-world env, an unknown render mode or a bad render size.
    """

    metadata: dict[str, Any] = {
        "name": "selfplaydrive_parallel_v0",
        "render_modes": list(RENDER_MODES),
        "render_fps": 10,  # one frame per step of the paper's dt = 0.1 s
        "is_parallelizable": True,
    }

    def __init__(self, env: Any, render_mode: str | None = None, render_size: int = 400) -> None:
        if env.num_worlds != 1:
            raise ValueError(
                f"DrivingParallelEnv: expected a VecEnv with num_worlds=1, got num_worlds={env.num_worlds}"
            )
        if render_mode is not None and render_mode not in RENDER_MODES:
            raise ValueError(f"render_mode: expected None or one of {RENDER_MODES}, got {render_mode!r}")
        if isinstance(render_size, bool) or not isinstance(render_size, int) or not 64 <= render_size <= 8192:
            raise ValueError(
                f"render_size: expected an integer number of pixels in [64, 8192], got {render_size!r}"
            )
        self.env = env
        self.render_mode = render_mode
        self.render_size = render_size
        self._renderer: Any = None
        self._scenario: Any = None
        self._log: Any = None
        if render_mode is not None:
            from selfplaydrive.render.record import attach_log

            # the log sees the scenarios of later resets (each `reset` here passes a seed, so
            # the native env samples again), which gives the camera its spawn region
            self._log = attach_log(env)
        self._closed = False
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
        if self._log is not None:
            self._scenario = self._log.scenario_of(self.env, 0)
        obs = observe(self.env)
        self.agents = [self.possible_agents[i] for i in np.flatnonzero(self.env.masks)]
        return {a: obs[self._slot[a]] for a in self.agents}, {a: {} for a in self.agents}

    def step(self, actions: dict[str, np.ndarray]) -> tuple[dict, dict, dict, dict, dict]:
        """Step the world; agents missing from `actions` brake fully with zero steering.

        Raises:
            ValueError: An action for an unknown agent or one not in `agents`, or an action
                outside the action space (a float or NaN index included).
            RuntimeError: After `close()`.
        """
        check_open(self._closed, "DrivingParallelEnv.step")
        live = set(self.agents)
        for name in actions:
            if name not in live:
                raise ValueError(f"actions: agent {name!r} is not in env.agents ({sorted(live)[:4]}...)")
        checked = {
            name: check_action(self.env.action_space, a, f"actions[{name!r}]") for name, a in actions.items()
        }
        if not self.agents:
            return {}, {}, {}, {}, {}
        env = self.env
        acts = static_actions(env.action_table, env.num_agents)
        for name, a in checked.items():
            acts[self._slot[name]] = a
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

    def render(self) -> np.ndarray | None:
        """Top-down image of the world's current state.

        Returns:
            (render_size, render_size, 3) uint8 RGB with `render_mode="rgb_array"`; None (and
            gymnasium's warning) without a render mode, as PettingZoo's envs do.

        Raises:
            RuntimeError: After `close()`.
        """
        check_open(self._closed, "DrivingParallelEnv.render")
        if self.render_mode is None:
            gym.logger.warn("DrivingParallelEnv.render: no render_mode was given, nothing is drawn")
            return None
        from selfplaydrive.render.episode import EpisodeRenderer
        from selfplaydrive.render.record import snapshot

        if self._renderer is None:  # matplotlib is imported and the figure made on first use
            self._renderer = EpisodeRenderer(self.env.maps, size=self.render_size, tail=0)
        if self._log is not None and self._log.pending:
            # the world was resampled inside `step` (autoreset) since the last look
            self._scenario = self._log.scenario_of(self.env, 0) or self._scenario
        return self._renderer.draw(snapshot(self.env, 0, self._scenario))

    def close(self) -> None:
        """Release the renderer's figure; later `step` and `render` calls raise."""
        self._renderer = None
        self._closed = True

    def _check_name(self, agent: str) -> None:
        if agent not in self._slot:
            raise ValueError(f"agent: expected one of agent_0..agent_{len(self._slot) - 1}, got {agent!r}")
