"""The one builder: Hydra config (or plain Python arguments) -> components -> `VecEnv`.

Every component is built from its `_target_` with `_convert_="all"`, so no `DictConfig` reaches
Cython or torch, and a component's constructor arguments are its config schema. Values that one
component shares with another have one source of truth: YAML interpolations
(`env.params.light_min: ${spawner.lights.time_left.0}`), or the builder passes one group's
object to another's constructor (the ``reward`` group's conditioning sampler to the spawner,
its constants and observed-coefficient scale into `SimParams`: `build_reward`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from selfplaydrive.errors import ConfigError, MapError
from selfplaydrive.maps.roadmap import RoadMap

CONFIG_MODULE = "selfplaydrive.conf"
GROUPS = (
    "map", "spawner", "physics", "reward", "obs", "env", "model", "trainer", "logger", "eval", "experiment",
)  # fmt: skip


def compose(config_name: str = "train", overrides: Sequence[str] = ()) -> Any:
    """Compose a packaged config with Hydra overrides (no run folder, no logging set-up).

    Raises:
        ConfigError: On an unknown group option or key, listing the valid choices.
    """
    from hydra import compose as hydra_compose
    from hydra import initialize_config_module
    from hydra.core.global_hydra import GlobalHydra

    if GlobalHydra.instance().is_initialized():
        GlobalHydra.instance().clear()
    with initialize_config_module(config_module=CONFIG_MODULE, version_base="1.3"):
        try:
            return hydra_compose(config_name=config_name, overrides=list(overrides))
        except Exception as exc:  # Hydra raises several exception types for bad overrides
            raise config_error(exc, config_name, overrides) from exc


def valid_options(group: str) -> list[str]:
    """Names of the shipped options of config group `group` (e.g. 'physics' -> ['bicycle', ...])."""
    from importlib import resources

    root = resources.files(CONFIG_MODULE)
    node = root
    for part in group.split("/"):
        node = node / part
    if not node.is_dir():
        return []
    return sorted(p.name[:-5] for p in node.iterdir() if p.name.endswith(".yaml"))


def valid_keys(cfg: Any, dotted: str) -> list[str]:
    """Keys of the config node at `dotted` ('' for the root), or [] if there is no such node."""
    from omegaconf import OmegaConf

    node = cfg
    for part in [p for p in dotted.split(".") if p]:
        if not OmegaConf.is_dict(node) or part not in node:
            return []
        node = node[part]
    return sorted(str(k) for k in node.keys()) if OmegaConf.is_dict(node) else []


def config_error(exc: Exception, config_name: str, overrides: Sequence[str]) -> ConfigError:
    """Turn a Hydra composition error into a `ConfigError` that lists the valid choices."""
    msg = str(exc)
    hints = []
    for ov in overrides:
        key = ov.split("=", 1)[0].lstrip("+~")
        moved = _moved_reward_key(key)
        if moved:
            hints.append(moved)
            continue
        if key in GROUPS or "/" in key:
            opts = valid_options(key)
            if opts:
                hints.append(f"valid options for '{key}': {', '.join(opts)}")
        else:  # a dotted key (reward.colision.high) or a top-level one (drivr=random)
            try:
                base = compose(config_name, [o for o in overrides if o != ov])
            except ConfigError:
                continue
            # list the keys of the deepest node that exists on the way to the bad key
            parts = key.split(".")
            for depth in range(len(parts) - 1, -1, -1):
                parent = ".".join(parts[:depth])
                keys = valid_keys(base, parent)
                if keys and parts[depth] not in keys:
                    hints.append(f"valid keys under '{parent or '<root>'}': {', '.join(keys)}")
                    break
    return ConfigError(msg if not hints else f"{msg}\n" + "\n".join(hints))


def _moved_reward_key(key: str) -> str:
    """A hint when `key` is a reward constant under its old place ``env.params``, else ''."""
    from selfplaydrive.sim.reward_settings import CONSTANTS

    name = key.removeprefix("env.params.")
    if name != key and name in CONSTANTS:
        return f"'{key}' moved to the reward group: use reward.{name}=... (docs/rewards.md)"
    return ""


def instantiate(node: Any, **kwargs: Any) -> Any:
    """`hydra.utils.instantiate` with `_convert_="all"` (plain Python containers only).

    Raises:
        ConfigError, MapError: What a component's constructor raised (Hydra's wrapper removed);
            other `ValueError`s of a constructor become a `ConfigError` naming the config key.
    """
    from hydra.errors import InstantiationException
    from hydra.utils import instantiate as hydra_instantiate

    try:
        return hydra_instantiate(node, _convert_="all", **kwargs)
    except InstantiationException as exc:
        cause = exc.__cause__
        if isinstance(cause, (ConfigError, MapError)):
            raise cause from None
        if isinstance(cause, ValueError):
            raise ConfigError(str(exc)) from cause
        raise


def build_maps(node: Any) -> list[RoadMap]:
    """Build the env's map(s): a map loader/`load_map`/`load_maps` node, or a list of such nodes."""
    from omegaconf import OmegaConf

    nodes = list(node) if OmegaConf.is_list(node) or isinstance(node, list) else [node]
    maps = []
    for item in nodes:
        obj = instantiate(item)
        if hasattr(obj, "load") and not isinstance(obj, RoadMap):
            obj = obj.load()
        several = list(obj) if isinstance(obj, (list, tuple)) else [obj]  # map=several: load_maps
        if not several or not all(isinstance(m, RoadMap) for m in several):
            raise ConfigError(
                f"map: expected a RoadMap, a list of them or a loader with .load(), got {type(obj).__name__}"
            )
        maps.extend(several)
    return maps


def build_reward(cfg: Any) -> Any:
    """The `RewardSettings` of a composed config's ``reward`` group (default: the paper's).

    A saved config of the old layout (reward constants under ``env.params``) is upgraded first
    (`selfplaydrive.sim.reward_settings.upgrade_run_config`).
    """
    from selfplaydrive.sim.reward_settings import RewardSettings, upgrade_run_config

    if "reward" not in cfg or cfg.reward is None:
        return RewardSettings()
    upgrade_run_config(cfg)
    settings = instantiate(cfg.reward)
    if not isinstance(settings, RewardSettings):
        raise ConfigError(
            f"reward: expected a selfplaydrive.sim.reward_settings.RewardSettings node, "
            f"got {type(settings).__name__}"
        )
    return settings


def build_spawner(cfg: Any, reward: Any = None) -> Any:
    """The spawner of `cfg.spawner`, drawing the coefficients of the ``reward`` group's sampler."""
    reward = reward if reward is not None else build_reward(cfg)
    return instantiate(cfg.spawner, conditioning=reward.conditioning)


def build_params(cfg: Any, reward: Any = None) -> Any:
    """`SimParams` of ``env.params`` with the ``reward`` group's constants and coefficient scale.

    Raises:
        ConfigError: ``env.params`` sets a reward constant (they live in ``reward``).
    """
    from selfplaydrive.sim.reward_settings import check_env_params

    reward = reward if reward is not None else build_reward(cfg)
    node = cfg.env.get("params") if "env" in cfg else None
    check_env_params(node)
    return reward.sim_params(instantiate(node) if node is not None else None)


def build_env(cfg: Any, **overrides: Any) -> Any:
    """Build the `VecEnv` of a composed config (groups map, spawner, physics, reward, obs, env).

    Args:
        cfg: The composed config.
        **overrides: Constructor arguments of `VecEnv` that replace the config's (e.g. hooks).
    """
    reward = build_reward(cfg)
    # an override replaces the config's part without building it (e.g. `maps` given: the
    # config's map file is not read)
    parts = {
        "maps": lambda: build_maps(cfg.map),
        "spawner": lambda: build_spawner(cfg, reward),
        "physics": lambda: instantiate(cfg.physics.model),
        "obs": lambda: instantiate(cfg.obs),
        "params": lambda: build_params(cfg, reward),
    }
    if reward.terms is not None:
        parts["reward"] = reward.linear_reward
    kwargs = {k: make() for k, make in parts.items() if k not in overrides}
    kwargs.update(overrides)
    # --- physics components: a model with its own action space (physics/components.py, e.g.
    # `physics=jerk`, `physics=delta`) brings it; env/actions configures the (accel, steer)
    # actions of the models that read the env's
    own = getattr(kwargs.get("physics"), "actions", None)
    if own is not None and "actions" not in overrides:
        kwargs["actions"] = own
    # --- end physics components
    _warn_unobserved_rules(kwargs.get("reward"), kwargs.get("obs"))
    # objects are passed to the partial, not to instantiate: Hydra would turn a dataclass such
    # as RoadMap into a structured config; env.params is built above (build_params)
    from omegaconf import OmegaConf, open_dict

    env_node: Any = OmegaConf.create(OmegaConf.to_container(cfg.env, resolve=True))
    with open_dict(env_node):
        if "params" in env_node:
            del env_node["params"]
    return instantiate(env_node, _partial_=True)(**kwargs)


# reward terms whose state only obs=rules shows (issue #15 item 1): STOP vs YIELD line types
# and crosswalk occupancy (docs/observation.md "Traffic-rule features")
RULES_OBSERVED = ("stop_sign", "crosswalk_yield")


def _warn_unobserved_rules(reward: Any, obs: Any) -> None:
    """Warn when a selected rule term depends on state the chosen encoder does not show."""
    import warnings

    from selfplaydrive.obs.rules import RulesEncoder

    names = [n for n in getattr(reward, "names", ()) if n in RULES_OBSERVED]
    if names and obs is not None and not isinstance(obs, RulesEncoder):
        warnings.warn(
            f"reward terms {names} are selected but the observation encoder "
            f"{getattr(obs, 'name', 'paper')!r} does not show STOP/YIELD line types or "
            "crosswalk occupancy; select obs=rules (the fix_* experiments do)",
            UserWarning,
            stacklevel=3,
        )


def make_env(
    map: RoadMap | str | Sequence[RoadMap | str] = "default",
    spawner: Any = None,
    physics: Any = None,
    reward: Any = None,
    obs: Any = None,
    num_worlds: int = 4,
    seed: int = 0,
    **env_kwargs: Any,
) -> Any:
    """Compose a `VecEnv` in plain Python, without Hydra.

    Args:
        map: A `RoadMap`, a `load_map` spec ("default", a path, "procedural:seed=1"), or a list.
        spawner: Any object with `sample(road_map, rng, map_index) -> Scenario`
            (default: `PaperSpawner` with `reward` as its conditioning sampler).
        physics: A physics model (default `FrictionBicycleModel()`).
        reward: A conditioning sampler for the reward coefficients (default: the paper's
            training distributions; ignored when `spawner` is given), a
            `selfplaydrive.rewards.LinearReward` selecting the env's reward terms, or a
            `selfplaydrive.sim.reward_settings.RewardSettings` (the ``reward`` group: sampler,
            terms, constants into `params`).
        obs: An `ObsConfig` (default: 63 objects, 200 road segments within 100 m).
        num_worlds: Worlds stepped together.
        seed: Seed of the first reset.
        **env_kwargs: Further `VecEnv` arguments (params, actions, num_threads, reward_hooks,
            obs_hooks, terminated_vehicle ...).

    Example:
        >>> from selfplaydrive.builder import make_env
        >>> env = make_env("default", num_worlds=2)
        >>> env.reset(seed=0).shape[0] == env.num_agents
        True
    """
    from selfplaydrive.maps.loader import load_map
    from selfplaydrive.scenario.spawner import PaperSpawner
    from selfplaydrive.sim.vec_env import VecEnv

    items: list[Any] = list(map) if isinstance(map, (list, tuple)) else [map]
    maps = [m if isinstance(m, RoadMap) else load_map(m) for m in items]
    from selfplaydrive.rewards.components import LinearReward
    from selfplaydrive.sim.reward_settings import RewardSettings

    if isinstance(reward, LinearReward):  # the terms, not the coefficients' sampler
        env_kwargs["reward"], reward = reward, None
    elif isinstance(reward, RewardSettings):  # everything the reward group holds
        env_kwargs["params"] = reward.sim_params(env_kwargs.get("params"))
        if reward.terms is not None:
            env_kwargs["reward"] = reward.linear_reward()
        reward = reward.conditioning
    if spawner is None:
        spawner = PaperSpawner(conditioning=reward) if reward is not None else PaperSpawner()
    return VecEnv(maps, spawner, num_worlds, physics=physics, obs=obs, seed=seed, **env_kwargs)


def build_model(cfg: Any, env: Any) -> Any:
    """Build the policy of `cfg.model`, filling the env-dependent sizes (layout, action dims)."""
    import numpy as np

    space = env.action_space
    nvec = [int(v) for v in np.asarray(getattr(space, "nvec", []))]
    if not nvec:
        raise ConfigError(
            f"model: the models need MultiDiscrete actions (env/actions=discrete, a physics model with a "
            f"value table), got {space}; continuous action spaces (physics=delta, env/actions=continuous) "
            f"train with trainer=sb3"
        )
    from dataclasses import asdict

    # the layout travels as a plain dict (max_objects, max_road, extra_dim): models accept either
    return instantiate(cfg.model, layout=asdict(env.layout), action_nvec=nvec)
