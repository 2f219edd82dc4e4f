"""Action sources for recording episodes: built-in drivers and trained checkpoints.

A policy is any callable `policy(observations, env) -> actions` with `observations` the env's
(N, obs_dim) float32 buffer and `actions` (N, 2) in the env's action space (table indices for
`DiscreteActions`); an optional `reset()` is called after the env's reset. `make_policy`
builds one from a name:

- "rule_based": `RuleBasedDriver` (docs/drivers.md);
- "random": `RandomDriver` (uniform actions);
- "static": `StaticDriver` (brake and stand);
- a path to a PPO checkpoint (`trainers/ppo/checkpoint.py`): `CheckpointPolicy`.

Checkpoints store the model's weights and the PPO settings but not the model's class or
constructor arguments; `model_from_checkpoint` finds them, in this order: a `model_spec`
entry of the payload (`{"_target_": "selfplaydrive.models.DeepSetsModel", ...kwargs}`, what a
trainer that wants exact round trips should save), the Hydra config of the run folder
(`<run>/.hydra/config.yaml` or `<run>/config.yaml` with a `model` node), else the sizes read
off the weights' shapes (`infer_model_spec`). The Transformer's head count does not change any
weight shape: pass `model_kwargs={"num_heads": H}` when the run did not use the paper's 4.
"""

from __future__ import annotations

import importlib
import os
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Protocol

import numpy as np

__all__ = ["BUILTIN", "CheckpointPolicy", "DriverPolicy", "Policy", "infer_model_spec", "make_policy"]

BUILTIN = ("rule_based", "random", "static")


class Policy(Protocol):
    """What `record_episode` calls each step."""

    def __call__(self, observations: np.ndarray, env: Any) -> np.ndarray:
        """(N, obs_dim) observations, the env -> (N, 2) actions."""
        ...


class DriverPolicy:
    """A built-in driver (`selfplaydrive.drivers`) as a policy: calls `driver.act()`."""

    def __init__(self, driver: Any) -> None:
        self.driver = driver

    def reset(self) -> None:
        if hasattr(self.driver, "reset"):
            self.driver.reset()

    def __call__(self, observations: np.ndarray, env: Any) -> np.ndarray:
        return self.driver.act()


def make_policy(spec: str | os.PathLike[str], env: Any, seed: int = 0, **checkpoint_kwargs: Any) -> Policy:
    """A policy for `env` from a name ("rule_based", "random", "static") or a checkpoint path.

    Args:
        spec: Built-in name or path of a `.pt` checkpoint.
        env: The `VecEnv` the policy drives.
        seed: Seed of the random driver.
        **checkpoint_kwargs: `CheckpointPolicy` arguments (deterministic, device, model_kwargs).

    Raises:
        ValueError: `spec` is neither a built-in name nor an existing file.
    """
    name = str(spec)
    if name in BUILTIN:
        from selfplaydrive.drivers import RandomDriver, RuleBasedDriver, StaticDriver

        if name == "rule_based":
            return DriverPolicy(RuleBasedDriver(env))
        if name == "random":
            return DriverPolicy(RandomDriver(env, seed=seed))
        return DriverPolicy(StaticDriver(env))
    if not Path(name).is_file():
        raise ValueError(
            f"driver {name!r}: expected one of {', '.join(BUILTIN)} or the path of a checkpoint file "
            "(no such file)"
        )
    return CheckpointPolicy(name, env, **checkpoint_kwargs)


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

    Raises:
        ValueError: The checkpoint does not fit the env (weights of another layout / action
            table) or holds no model.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        env: Any,
        deterministic: bool = True,
        device: str = "cpu",
        model_kwargs: Mapping[str, Any] | None = None,
        seed: int = 0,
    ) -> None:
        import torch

        from selfplaydrive.trainers.ppo import checkpoint as ckpt

        self.path = Path(path)
        payload = ckpt.load(self.path, map_location=device)
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
        ValueError: No weights in the payload, or weights that do not fit the env's layout.
    """
    weights = payload.get("model")
    if not isinstance(weights, Mapping) or not weights:
        raise ValueError(f"checkpoint {path}: expected the model's weights under key 'model', found none")
    spec = payload.get("model_spec") or _run_config_spec(path) or infer_model_spec(weights)
    spec = dict(spec)
    target = spec.pop("_target_")
    spec.update(model_kwargs or {})
    nvec = getattr(env.action_space, "nvec", None)
    if nvec is None:
        raise ValueError(
            f"checkpoint {path}: trained models act in DiscreteActions; this env has continuous actions"
        )
    spec["layout"] = env.layout
    spec["action_nvec"] = tuple(int(n) for n in nvec)
    module, _, cls_name = target.rpartition(".")
    cls = getattr(importlib.import_module(module), cls_name)
    model = cls(**spec)
    try:
        model.load_state_dict(dict(weights))
    except RuntimeError as exc:  # size mismatches: another observation layout or action table
        raise ValueError(
            f"checkpoint {path}: its {cls_name} weights do not fit this env (obs_dim "
            f"{env.layout.obs_dim}, actions {spec['action_nvec']}); expected the env the model was "
            f"trained on.\n{exc}"
        ) from exc
    return model


def _run_config_spec(path: Path) -> dict[str, Any] | None:
    """The `model` node of the run folder's Hydra config (checkpoint in <run>/checkpoints/)."""
    for run in (path.parent.parent, path.parent):
        for cfg_file in (run / ".hydra" / "config.yaml", run / "config.yaml"):
            if not cfg_file.is_file():
                continue
            from omegaconf import OmegaConf

            node = OmegaConf.load(cfg_file).get("model")
            if node is not None and "_target_" in node:
                spec = OmegaConf.to_container(node, resolve=False)
                # layout and action_nvec are filled from the env; drop interpolations
                return {k: v for k, v in spec.items() if k not in ("layout", "action_nvec")}
    return None


def infer_model_spec(weights: Mapping[str, Any]) -> dict[str, Any]:
    """Model class and sizes read off the weights' shapes.

    Args:
        weights: A `DeepSetsModel` or `TransformerModel` state dict.

    Returns:
        {"_target_": class path, size arguments...}.

    Raises:
        ValueError: Weights of neither model.
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
    raise ValueError(
        "checkpoint weights: expected a DeepSetsModel (lstm.*) or TransformerModel (ego_proj.*, query) "
        f"state dict, got keys {sorted(weights)[:6]} ..."
    )
