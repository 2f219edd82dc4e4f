"""Action sources by name: built-in drivers and trained checkpoints, and the env a checkpoint
was trained in.

A policy is any callable `policy(observations, env) -> actions` with `observations` the env's
(N, obs_dim) float32 buffer and `actions` (N, 2) in the env's action space (table indices for
`DiscreteActions`); an optional `reset()` is called after the env's reset. `make_policy`
builds one from a name:

- "rule_based": `RuleBasedDriver` (docs/drivers.md);
- "random": `RandomDriver` (uniform actions);
- "static": `StaticDriver` (brake and stand);
- a path to a PPO checkpoint (`trainers/ppo/checkpoint.py`): `CheckpointPolicy`;
- "pretrained": the policy shipped with the library (`selfplaydrive.pretrained`), a checkpoint
  whose run config lies next to it.

Checkpoints store the model's weights and the PPO settings but not the model's class or
constructor arguments; `model_from_checkpoint` finds them, in this order: a `model_spec`
entry of the payload (`{"_target_": "selfplaydrive.models.DeepSetsModel", ...kwargs}`), the
`model` node of the training run's config (`find_run_config`), else the sizes read off the
weights' shapes (`infer_model_spec`). The Transformer's head count does not change any weight
shape: pass `model_kwargs={"num_heads": H}` when the run did not use the paper's 4.

A model only fits the observation layout and action table it was trained with.
`trained_env_kwargs(run_cfg)` gives the `VecEnv` arguments that fix them (observation sizes,
action table, observation scales and simulator parameters, physics) from the run's config:
`<run>/resolved_config.yaml`, written by `selfplaydrive train` next to `<run>/checkpoints/`.

This module imports torch only where a checkpoint is loaded.
"""

from __future__ import annotations

import importlib
import os
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from selfplaydrive._optional import requires_extra
from selfplaydrive.errors import CheckpointError

__all__ = [
    "BUILTIN",
    "RUN_CONFIG_FILES",
    "CheckpointPolicy",
    "DriverPolicy",
    "Policy",
    "find_run_config",
    "infer_model_spec",
    "is_builtin",
    "load_checkpoint",
    "load_run_config",
    "make_policy",
    "model_from_checkpoint",
    "trained_env_kwargs",
    "trained_obs_dim",
]

BUILTIN = ("rule_based", "random", "static")
# Looked for in the checkpoint's run folder, first match wins: what `selfplaydrive train` writes
# (resolved), then Hydra's own copy (unresolved), then a hand-written config.
RUN_CONFIG_FILES = ("resolved_config.yaml", ".hydra/config.yaml", "config.yaml")


class Policy(Protocol):
    """What `record_episode` and the evaluations call each step."""

    def __call__(self, observations: np.ndarray, env: Any) -> np.ndarray:
        """(N, obs_dim) observations, the env -> (N, 2) actions."""
        ...


class DriverPolicy:
    """A built-in driver (`selfplaydrive.drivers`) as a policy: calls `driver.act()`."""

    def __init__(self, driver: Any) -> None:
        self.driver = driver

    def reset(self) -> None:
        """Forward to the driver's `reset()` where it has one."""
        if hasattr(self.driver, "reset"):
            self.driver.reset()

    def __call__(self, observations: np.ndarray, env: Any) -> np.ndarray:
        return self.driver.act()


def is_builtin(spec: str | os.PathLike[str]) -> bool:
    """True for the names of the built-in drivers ("rule_based", "random", "static")."""
    return str(spec) in BUILTIN


def make_policy(spec: str | os.PathLike[str], env: Any, seed: int = 0, **checkpoint_kwargs: Any) -> Policy:
    """A policy for `env` from a name ("rule_based", "random", "static", "pretrained") or a
    checkpoint path.

    Args:
        spec: Built-in name, "pretrained" (the shipped checkpoint) or path of a `.pt` checkpoint.
        env: The `VecEnv` the policy drives.
        seed: Seed of the random driver.
        **checkpoint_kwargs: `CheckpointPolicy` arguments (deterministic, device, model_kwargs,
            payload).

    Raises:
        CheckpointError: `spec` is neither a built-in name nor a readable checkpoint (a
            `ValueError`, so callers that catch those keep working).
    """
    from selfplaydrive.pretrained import resolve_spec

    name = resolve_spec(spec)
    if is_builtin(name):
        from selfplaydrive.drivers import RandomDriver, RuleBasedDriver, StaticDriver

        if name == "rule_based":
            return DriverPolicy(RuleBasedDriver(env))
        if name == "random":
            return DriverPolicy(RandomDriver(env, seed=seed))
        return DriverPolicy(StaticDriver(env))
    if not Path(name).is_file():
        raise CheckpointError(
            f"driver {name!r}: expected one of {', '.join(BUILTIN)}, pretrained or the path of a checkpoint "
            "file (no such file)",
            name,
        )
    return CheckpointPolicy(name, env, **checkpoint_kwargs)


def load_checkpoint(path: str | os.PathLike[str], map_location: str = "cpu") -> dict[str, Any]:
    """Read a checkpoint written by `selfplaydrive train` (`trainers/ppo/checkpoint.py`).

    Args:
        path: The `.pt` file.
        map_location: Torch device the tensors are loaded to.

    Returns:
        The payload (at least the model's weights under "model").

    Raises:
        CheckpointError: No such file, a file that is not a selfplaydrive checkpoint, or one
            without model weights; the message names the file.
    """
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(
            "no such file; expected a checkpoint written by `selfplaydrive train` "
            "(<run>/checkpoints/final.pt or ckpt_<update>.pt)",
            path,
        )
    with requires_extra("torch"):
        from selfplaydrive.trainers.ppo import checkpoint as ckpt
    try:
        payload = ckpt.load(path, map_location=map_location, required=ckpt.POLICY_KEYS)
    except CheckpointError:
        raise
    except Exception as exc:  # torch.load fails on foreign files with many types (pickle, zip, EOF ...)
        raise CheckpointError(
            f"not a selfplaydrive checkpoint ({type(exc).__name__}: {exc}); expected a file written by "
            "`selfplaydrive train`",
            path,
        ) from exc
    if not isinstance(payload, Mapping):
        raise CheckpointError(
            f"holds a {type(payload).__name__}; expected a checkpoint dict with the model's weights "
            "under 'model'",
            path,
        )
    weights = payload.get("model")
    if not isinstance(weights, Mapping) or not weights:
        raise CheckpointError(
            f"expected the model's weights under key 'model', found keys {sorted(map(str, payload))[:8]}",
            path,
        )
    return dict(payload)


def find_run_config(checkpoint: str | os.PathLike[str]) -> Path | None:
    """The config of the training run a checkpoint belongs to, or None.

    Looks in the checkpoint's folder's parent (`<run>/checkpoints/x.pt` -> `<run>`), then in the
    checkpoint's own folder, for `RUN_CONFIG_FILES` in that order.
    """
    path = Path(checkpoint)
    for run in (path.parent.parent, path.parent):
        for name in RUN_CONFIG_FILES:
            if (run / name).is_file():
                return run / name
    return None


def load_run_config(path: str | os.PathLike[str]) -> Any:
    """Load and resolve a training run's config (a `DictConfig`).

    Raises:
        CheckpointError: The file is missing, not YAML, or lacks the `obs` and `env` nodes a
            training config has.
    """
    from omegaconf import OmegaConf

    path = Path(path)
    if not path.is_file():
        raise CheckpointError("run config: no such file; expected <run>/resolved_config.yaml", path)
    try:
        cfg = OmegaConf.load(path)
    except Exception as exc:  # yaml and omegaconf raise several types for a malformed file
        raise CheckpointError(f"run config: not a YAML config ({type(exc).__name__}: {exc})", path) from exc
    missing = [k for k in ("obs", "env") if not OmegaConf.is_dict(cfg) or k not in cfg]
    if missing:
        raise CheckpointError(
            f"run config: no {' and no '.join(repr(k) for k in missing)} node; expected the config of a "
            "`selfplaydrive train` run (resolved_config.yaml)",
            path,
        )
    from selfplaydrive.sim.reward_settings import upgrade_run_config

    return upgrade_run_config(cfg)  # a config saved before the reward group held every setting


def trained_env_kwargs(run_cfg: Any) -> dict[str, Any]:
    """`VecEnv` arguments that reproduce a training run's observation and action spaces.

    Taken from the run's config: `obs` (observation sizes and radius), `env.actions` (action
    table), `env.params` (observation scales, time step, simulator parameters) with the
    ``reward`` group's constants and observed-coefficient scale (derived from the training
    ranges: the observation the policy learned on), `env.terminated_vehicle` and
    `physics.model`. Not taken: the maps, the spawner and the coefficient distributions
    (evaluations set their own), `num_worlds`, threads and seed.

    Args:
        run_cfg: The run's config (`load_run_config`).

    Returns:
        {"obs", "actions", "params", "physics", "terminated_vehicle"} (those present).
    """
    from selfplaydrive.builder import build_params, instantiate

    env = run_cfg.env
    kwargs: dict[str, Any] = {"obs": instantiate(run_cfg.obs)}
    if "actions" in env:
        kwargs["actions"] = instantiate(env.actions)
    if "params" in env or "reward" in run_cfg:
        kwargs["params"] = build_params(run_cfg)
    if "terminated_vehicle" in env:
        kwargs["terminated_vehicle"] = str(env.terminated_vehicle)
    if "physics" in run_cfg and "model" in run_cfg.physics:
        kwargs["physics"] = instantiate(run_cfg.physics.model)
        own = getattr(kwargs["physics"], "actions", None)
        if own is not None:  # a model with its own action space brings it (builder.build_env)
            kwargs["actions"] = own
    return kwargs


def trained_obs_dim(payload: Mapping[str, Any]) -> int | None:
    """Width of the observation rows the checkpoint's env produced, or None when the payload
    holds no env state (a checkpoint saved with the model only)."""
    env = payload.get("env")
    if not isinstance(env, Mapping):
        return None
    obs = env.get("buffers.obs")  # `VecEnv.get_state()` (checkpoint format 2)
    if obs is None:  # format 1: the buffers as a nested dict
        buffers = env.get("buffers")
        obs = buffers.get("obs") if isinstance(buffers, Mapping) else None
    shape = getattr(obs, "shape", None)
    return int(shape[-1]) if shape is not None and len(shape) == 2 else None


class CheckpointPolicy:
    """A trained model (`selfplaydrive.models`) loaded from a PPO checkpoint.

    Keeps each agent slot's recurrent state (Deep Sets LSTM) and zeroes it where a new episode
    starts in that slot, as the trainer does (`PPOTrainer.env_step`): at the first call, and
    for slots that did not act last step or whose agent ended (terminated or truncated).

    Args:
        path: Checkpoint file written by `PPOTrainer.save` / `checkpoint.save`.
        env: The `VecEnv` to drive (its observation layout must match the model's).
        deterministic: Take the most likely action (default) instead of sampling.
        device: Torch device for the forward pass.
        model_kwargs: Constructor arguments that override the stored or inferred ones.
        seed: Seed of the sampling generator (when not deterministic).
        payload: The already loaded checkpoint (`load_checkpoint(path)`), to build a policy
            for several envs without reading the file each time.

    Raises:
        CheckpointError: The file is no checkpoint, or its weights do not fit the env (another
            observation layout or action table).
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        env: Any,
        deterministic: bool = True,
        device: str = "cpu",
        model_kwargs: Mapping[str, Any] | None = None,
        seed: int = 0,
        payload: Mapping[str, Any] | None = None,
    ) -> None:
        with requires_extra("torch"):
            import torch

        self.path = Path(path)
        if payload is None:
            payload = load_checkpoint(self.path, map_location=device)
        self.model = model_from_checkpoint(payload, env, self.path, model_kwargs).to(device).eval()
        self.device = torch.device(device)
        self.deterministic = deterministic
        self.generator = torch.Generator(device=self.device).manual_seed(seed)
        self.env = env
        self.reset()

    def reset(self) -> None:
        """Forget the recurrent state (call after the env's reset)."""
        self.state = self.model.initial_state(self.env.num_agents, self.device)
        self.prev_acted: np.ndarray | None = None

    def __call__(self, observations: np.ndarray, env: Any) -> np.ndarray:
        with requires_extra("torch"):
            import torch

            from selfplaydrive.models.common import sample_actions

        masks = np.asarray(env.masks, dtype=bool)
        if self.prev_acted is None:
            start = np.ones_like(masks)
        else:
            ended = np.asarray(env.terminations, bool) | np.asarray(env.truncations, bool)
            start = masks & (~self.prev_acted | ended)
        self.prev_acted = masks.copy()
        with torch.no_grad():
            obs = torch.tensor(observations, dtype=torch.float32, device=self.device)  # a copy
            logits, _, self.state = self.model(obs, self.state, torch.from_numpy(start).to(self.device))
            actions = sample_actions(
                logits.float(), self.model.nvec, self.deterministic, generator=self.generator
            )
        return actions.cpu().numpy().astype(np.int64)


def model_from_checkpoint(
    payload: Mapping[str, Any], env: Any, path: Path, model_kwargs: Mapping[str, Any] | None = None
) -> Any:
    """Build the checkpoint's model for `env` and load its weights (see the module docstring
    for where the class and sizes come from).

    Raises:
        CheckpointError: No weights in the payload, or weights that do not fit the env's layout.
    """
    weights = payload.get("model")
    if not isinstance(weights, Mapping) or not weights:
        raise CheckpointError("expected the model's weights under key 'model', found none", path)
    trained = trained_obs_dim(payload)
    if trained is not None and trained != env.layout.obs_dim:
        # Deep Sets' weights do not depend on the set sizes, so they would load into an env with
        # other max_road / max_objects and drive on features unlike those they learnt from
        raise CheckpointError(
            f"trained on observation rows of width {trained}, this env's are {env.layout.obs_dim} "
            "wide; expected the observation sizes of the run it was trained in (its "
            "resolved_config.yaml `obs` group)",
            path,
        )
    spec = dict(payload.get("model_spec") or _run_config_spec(path) or infer_model_spec(weights))
    target = spec.pop("_target_")
    spec.update(model_kwargs or {})
    nvec = getattr(env.action_space, "nvec", None)
    if nvec is None:
        raise CheckpointError("trained models act in DiscreteActions; this env has continuous actions", path)
    spec["layout"] = env.layout
    spec["action_nvec"] = tuple(int(n) for n in nvec)
    module, _, cls_name = target.rpartition(".")
    cls = getattr(importlib.import_module(module), cls_name)
    model = cls(**spec)
    try:
        model.load_state_dict(dict(weights))
    except RuntimeError as exc:  # size mismatches: another observation layout or action table
        raise CheckpointError(
            f"its {cls_name} weights do not fit this env (obs_dim {env.layout.obs_dim}, actions "
            f"{spec['action_nvec']}); expected the env the model was trained on.\n{exc}",
            path,
        ) from exc
    return model


def _run_config_spec(path: Path) -> dict[str, Any] | None:
    """The `model` node of the run's config (layout and action_nvec left to the env)."""
    cfg_file = find_run_config(path)
    if cfg_file is None:
        return None
    from omegaconf import OmegaConf

    node = OmegaConf.load(cfg_file).get("model")
    if node is None or "_target_" not in node:
        return None
    spec = OmegaConf.to_container(node, resolve=False)
    # layout and action_nvec are filled from the env (and are "???" in a saved config)
    return {k: v for k, v in spec.items() if k not in ("layout", "action_nvec")}


def infer_model_spec(weights: Mapping[str, Any]) -> dict[str, Any]:
    """Model class and sizes read off the weights' shapes.

    Args:
        weights: A `DeepSetsModel` or `TransformerModel` state dict.

    Returns:
        {"_target_": class path, size arguments...}.

    Raises:
        CheckpointError: Weights of neither model.
    """
    if "lstm.weight_ih_l0" in weights:
        return {
            "_target_": "selfplaydrive.models.DeepSetsModel",
            "input_size": int(weights["ego_encoder.0.weight"].shape[0]),
            "hidden_size": int(weights["shared.1.weight"].shape[0]),
            "lstm_size": int(weights["lstm.weight_hh_l0"].shape[1]),
        }
    if "ego_proj.weight" in weights and "query" in weights:

        def blocks(prefix: str) -> int:
            found = {int(m.group(1)) for k in weights if (m := re.match(rf"{prefix}\.(\d+)\.", k))}
            return max(found) + 1 if found else 0

        return {
            "_target_": "selfplaydrive.models.TransformerModel",
            "embed_size": int(weights["ego_proj.weight"].shape[0]),
            "num_encoder_blocks": blocks("encoder"),
            "num_decoder_blocks": blocks("decoder"),
            "ffn_size": int(weights["encoder.0.ffn.0.weight"].shape[0]),
            "film_hidden": int(weights["film.0.weight"].shape[0]),
        }
    raise CheckpointError(
        "checkpoint weights: expected a DeepSetsModel (lstm.*) or TransformerModel (ego_proj.*, query) "
        f"state dict, got keys {sorted(weights)[:6]} ..."
    )
