"""Gymnasium ids of the adapters (docs/interfaces/gymnasium.md).

- ``gymnasium.make("selfplaydrive/SingleAgent-v0", ...)``: a `SingleAgentEnv` (one ego vehicle
  in one world, the others driven by ``others``); ``gymnasium.make_vec`` of this id gives
  gymnasium's own sync/async vector of such envs.
- ``gymnasium.make_vec("selfplaydrive/SelfPlay-v0", num_envs=N, ...)``: a `GymVectorEnv`
  whose N sub-envs are the agent slots of N / agents-per-world worlds, all learners (self-play).

`register_envs` runs on ``import selfplaydrive``. The entry points are strings, so registering
imports gymnasium only: the simulator, the maps and the drivers load when an env is made.
"""

from __future__ import annotations

from typing import Any

import gymnasium

SINGLE_AGENT_ID = "selfplaydrive/SingleAgent-v0"
SELF_PLAY_ID = "selfplaydrive/SelfPlay-v0"
DEFAULT_AGENTS = 32  # agent slots per world of the paper's spawner (section 2.2)


def register_envs() -> None:
    """Register both ids with gymnasium (a second call changes nothing)."""
    if SINGLE_AGENT_ID not in gymnasium.registry:
        gymnasium.register(id=SINGLE_AGENT_ID, entry_point=f"{__name__}:make_single_agent_env")
    if SELF_PLAY_ID not in gymnasium.registry:
        # no single-env entry point: a sub-env is an agent slot, not something to make alone
        gymnasium.register(id=SELF_PLAY_ID, vector_entry_point=f"{__name__}:make_self_play_vector_env")


def make_single_agent_env(
    map: Any = "default",
    others: Any = "rule_based",
    spawner: Any = None,
    seed: int = 0,
    render_mode: None = None,
    **env_kwargs: Any,
) -> Any:
    """Entry point of ``selfplaydrive/SingleAgent-v0``: a one-world `SingleAgentEnv`.

    Args:
        map: A `RoadMap`, a `load_map` spec ("default", a path, "procedural:seed=1") or a list.
        others: How the other vehicles act (`SingleAgentEnv`): "rule_based", "static" or a
            callable policy.
        spawner: A dict of `PaperSpawner` arguments (e.g. ``{"num_agents": 8}``; default: the
            paper's spawner, with ``reward`` as its conditioning sampler when given), or a
            spawner object. Prefer the dict: gymnasium deep-copies the arguments into
            ``env.spec``, and a spawner holding Cython kernels cannot be copied (gymnasium
            then warns and leaves ``env.spec`` None).
        seed: Seed of the native env's first reset.
        render_mode: Must be None (the env draws nothing).
        **env_kwargs: Further `selfplaydrive.make_env` / `VecEnv` arguments (physics, actions,
            obs, params, reward ...).

    Returns:
        The `SingleAgentEnv`.
    """
    from selfplaydrive.env.gym_single import SingleAgentEnv

    native = _native(map, spawner, 1, seed, env_kwargs)
    return SingleAgentEnv(native, others=others, render_mode=render_mode)


def make_self_play_vector_env(
    num_envs: int,
    map: Any = "default",
    spawner: Any = None,
    seed: int = 0,
    render_mode: None = None,
    **env_kwargs: Any,
) -> Any:
    """Vector entry point of ``selfplaydrive/SelfPlay-v0``: a `GymVectorEnv`.

    Args:
        num_envs: Sub-envs, that is agent slots in all: a positive multiple of the slots per
            world (the spawner's ``num_agents``, 32 by default); the env steps
            num_envs / slots-per-world worlds.
        map, spawner, seed, **env_kwargs: As for `make_single_agent_env`.
        render_mode: Must be None (the env draws nothing).

    Returns:
        The `GymVectorEnv` (its ``num_envs`` equals `num_envs`).

    Raises:
        ValueError: When `num_envs` is not a positive multiple of the slots per world, or the
            spawner's scenarios hold another number of slots.
    """
    from selfplaydrive.env.gym_vector import GymVectorEnv

    per_world = _slots_per_world(spawner)
    if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1 or num_envs % per_world:
        raise ValueError(
            f"num_envs: expected a positive multiple of the {per_world} agent slots per world "
            f"(each sub-env is one agent slot), got {num_envs!r}"
        )
    native = _native(map, spawner, num_envs // per_world, seed, env_kwargs)
    if native.num_agents != num_envs:
        raise ValueError(
            f"num_envs: expected {native.agents_per_world} agent slots per world (the spawner's "
            f"scenarios), so a multiple of {native.agents_per_world}; got {num_envs}"
        )
    return GymVectorEnv(native, render_mode=render_mode)


def _slots_per_world(spawner: Any) -> int:
    """Agent slots per world that `spawner` (a dict of `PaperSpawner` arguments, an object or
    None) asks for; the native env's own count is checked after it is built."""
    if spawner is None:
        return DEFAULT_AGENTS
    if isinstance(spawner, dict):
        return int(spawner.get("num_agents", DEFAULT_AGENTS))
    return int(getattr(spawner, "num_agents", DEFAULT_AGENTS))


def _native(map: Any, spawner: Any, num_worlds: int, seed: int, kwargs: dict[str, Any]) -> Any:
    """The native `VecEnv` built by `selfplaydrive.make_env`."""
    from selfplaydrive.builder import make_env

    if spawner is None or isinstance(spawner, dict):
        from selfplaydrive.rewards.components import LinearReward
        from selfplaydrive.scenario.spawner import PaperSpawner

        args = dict(spawner or {})
        reward = kwargs.get("reward")
        if reward is not None and not isinstance(reward, LinearReward):
            # a RewardSettings (the reward group) stays for make_env: its terms and constants
            sampler = getattr(reward, "conditioning", None)
            if sampler is None:
                sampler = kwargs.pop("reward")
            args.setdefault("conditioning", sampler)
        spawner = PaperSpawner(**args)
    return make_env(map, spawner=spawner, num_worlds=num_worlds, seed=seed, **kwargs)
