"""`trainer=sb3`: the quick-baseline path, stable-baselines3 PPO through `SB3VecEnv`.

The policy reads the observation with a Deep Sets feature extractor (paper section 3): one MLP
per modality (ego + coefficients, each object, each road segment), a masked element-wise max
over the object and road sets, and a linear layer over the three pooled vectors. It has no
LSTM (SB3's PPO is feed-forward), so it is a baseline, not the paper's model; use `trainer=ppo`
for that. Per-slot conventions of the adapter (inactive slots, truncation bootstrapping) are in
docs/interfaces/sb3.md.

Run folder (next to Hydra's resolved_config.yaml and run_meta.json):
    sb3_config.json    the `SB3Trainer` arguments used
    tb/                SB3's TensorBoard scalars (rollout/, train/) plus the episode metrics of
                       the native env under the PPO trainer's tag names (term/<name>,
                       charts/waypoint_completion, charts/collision_rate, ...); the `logger`
                       group picks where they go (logger=jsonl: metrics.jsonl; none: nowhere)
    model.zip          `stable_baselines3.PPO.save` (load with `PPO.load`)
    eval.json          evaluation summary (waypoint completion, collision / off-road rates, ...)
"""

from __future__ import annotations

import json
import math
import sys
from collections.abc import Mapping, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces

from selfplaydrive._optional import requires_extra
from selfplaydrive.errors import ConfigError
from selfplaydrive.models.common import ObsSplitter, mlp
from selfplaydrive.models.pooling import compact_sets, masked_max
from selfplaydrive.obs.layout import ObsLayout
from selfplaydrive.trainers.ppo.episodes import EpisodeTracker, summarize

with requires_extra("torch"):
    import torch
    from torch import Tensor, nn

with requires_extra("sb3"):
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.logger import KVWriter
    from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

EVAL_SEED_OFFSET = 1_000_003  # evaluation worlds never repeat the training seed's worlds
DEVICES = ("auto", "cpu", "cuda")


class DeepSetsExtractor(BaseFeaturesExtractor):
    """Deep Sets encoder of a flat observation row (paper section 3, without the LSTM).

    Args:
        observation_space: The env's Box (its width must be the layout's `obs_dim`).
        layout: The env's `ObsLayout` or its fields as a mapping (`dataclasses.asdict`).
        embed_size: Width of every per-modality embedding.
        features_dim: Width of the output handed to SB3's policy and value heads.

    Shapes: forward maps (B, obs_dim) float32 to (B, features_dim). The output does not depend
    on the order of the object or road elements, nor on padded (valid = 0) elements.
    """

    def __init__(
        self,
        observation_space: spaces.Box,
        layout: ObsLayout | Mapping[str, int],
        embed_size: int = 64,
        features_dim: int = 256,
    ) -> None:
        super().__init__(observation_space, features_dim)
        self.splitter = ObsSplitter(layout)
        width = self.splitter.layout.obs_dim
        if observation_space.shape != (width,):
            raise ConfigError(
                f"DeepSetsExtractor: observation space shape {observation_space.shape} does not match "
                f"the layout's obs_dim {width} ({self.splitter.layout})"
            )
        s = self.splitter
        self.ego = mlp([s.ego_in, embed_size, embed_size], final_act=True)
        self.objects = mlp([s.object_in, embed_size, embed_size])
        self.road = mlp([s.road_in, embed_size, embed_size])
        self.head = nn.Sequential(nn.Linear(3 * embed_size, features_dim), nn.ReLU())

    def forward(self, observations: Tensor) -> Tensor:
        parts = self.splitter(observations.float())
        ego = self.ego(parts["ego"])
        obj, obj_valid = compact_sets(parts["objects"], parts["object_valid"])
        road, road_valid = compact_sets(parts["road"], parts["road_valid"])
        pooled_obj = masked_max(self.objects(obj), obj_valid)
        pooled_road = masked_max(self.road(road), road_valid)
        return self.head(torch.cat([ego, pooled_obj, pooled_road], dim=1))


class EpisodeMetricsCallback(BaseCallback):
    """Logs the native env's episode metrics at the end of each rollout, under the same tag
    names as the library's PPO trainer (`term/<name>` and `charts/<metric>`), so the two paths
    read alike in TensorBoard (docs/training.md, "Reading the logs")."""

    def __init__(self, native_env) -> None:
        super().__init__()
        self.native = native_env
        self.tracker = EpisodeTracker(native_env)
        self.last: dict[str, float] = {}

    def _on_training_start(self) -> None:
        self.tracker.on_reset()  # SB3 reset the env in `learn`

    def _on_step(self) -> bool:
        self.tracker.on_step(self.native.reward_mask.copy())  # slots that acted in this step
        return True

    def _on_rollout_end(self) -> None:
        records, returns = self.tracker.pop()
        metrics = summarize(records, returns)
        for key, value in metrics.items():
            if math.isfinite(value):
                self.logger.record(key if "/" in key else f"charts/{key}", value)
        if records:
            self.last = metrics


class LoggerWriter(KVWriter):
    """An SB3 output format that hands each dump of SB3's logger (once per rollout) to a
    library logger (`trainers/ppo/logging.py`): `scalars(values, step)` with SB3's keys as tags
    (keys SB3 keeps out of TensorBoard are left out), then `progress(1, values)`."""

    def __init__(self, logger: Any) -> None:
        self.logger = logger

    def write(self, key_values: dict[str, Any], key_excluded: dict[str, Any], step: int = 0) -> None:
        values = {
            k: v
            for k, v in key_values.items()
            if not (key_excluded.get(k) and "tensorboard" in key_excluded[k])
        }
        self.logger.scalars(values, step)
        self.logger.progress(1, values)

    def close(self) -> None:
        self.logger.close()


class SB3Trainer:
    """stable-baselines3 PPO with a Deep Sets extractor; the constructor arguments are the
    schema of `conf/trainer/sb3.yaml`.

    Args:
        total_timesteps: Budget in slot-steps (SB3 counts every agent slot of every step).
        n_steps: Env steps per rollout (the buffer holds n_steps x agent slots).
        batch_size: Minibatch size in slot-steps.
        n_epochs: Passes over each rollout.
        learning_rate: Adam step size.
        gamma: Discount per 0.1 s step.
        gae_lambda: GAE lambda.
        clip_range: PPO ratio clip.
        ent_coef: Entropy bonus coefficient.
        vf_coef: Value loss coefficient.
        max_grad_norm: Gradient clipping norm.
        embed_size: Per-modality embedding width of the extractor.
        features_dim: Extractor output width.
        net_arch: Hidden widths of the policy and value MLPs after the extractor.
        eval_episodes: World-episodes in the final evaluation (0 skips it).
        eval_max_steps: Env-step cap of the evaluation.
        eval_deterministic: Greedy actions in the evaluation.
        seed: Seed of SB3, torch and the env's first reset.
        device: "auto", "cpu" or "cuda" (or "cuda:N").
        torch_threads: Torch CPU threads (0 keeps torch's default).
        progress_bar: SB3's progress bar (needs tqdm and rich).
        verbose: SB3 verbosity (0 silent, 1 prints the rollout/train tables).

    Raises:
        ConfigError: On a value out of range, naming the `trainer.<key>`.
    """

    def __init__(
        self,
        total_timesteps: int = 200_000,
        n_steps: int = 64,
        batch_size: int = 2048,
        n_epochs: int = 4,
        learning_rate: float = 3e-4,
        gamma: float = 0.99,
        gae_lambda: float = 0.95,
        clip_range: float = 0.2,
        ent_coef: float = 0.005,
        vf_coef: float = 0.5,
        max_grad_norm: float = 0.5,
        embed_size: int = 64,
        features_dim: int = 256,
        net_arch: Sequence[int] = (128,),
        eval_episodes: int = 8,
        eval_max_steps: int = 2000,
        eval_deterministic: bool = False,
        seed: int = 0,
        device: str = "auto",
        torch_threads: int = 0,
        progress_bar: bool = False,
        verbose: int = 0,
    ) -> None:
        for name in ("total_timesteps", "n_steps", "batch_size", "n_epochs", "embed_size", "features_dim"):
            _check(name, locals()[name], lambda v: int(v) == v and v >= 1, "an integer >= 1")
        for name in ("eval_episodes", "eval_max_steps", "torch_threads", "seed", "verbose"):
            _check(name, locals()[name], lambda v: int(v) == v and v >= 0, "an integer >= 0")
        _check("learning_rate", learning_rate, lambda v: v > 0, "a number > 0")
        for name in ("gamma", "gae_lambda"):
            _check(name, locals()[name], lambda v: 0 <= v <= 1, "a number in [0, 1]")
        for name in ("clip_range", "vf_coef", "max_grad_norm"):
            _check(name, locals()[name], lambda v: v > 0, "a number > 0")
        _check("ent_coef", ent_coef, lambda v: v >= 0, "a number >= 0")
        _check(
            "net_arch", net_arch, lambda v: all(int(w) == w and w >= 1 for w in v), "a list of widths >= 1"
        )
        _check("device", device, lambda v: str(v).split(":")[0] in DEVICES, f"one of {DEVICES} or cuda:N")
        self.total_timesteps = int(total_timesteps)
        self.n_steps = int(n_steps)
        self.batch_size = int(batch_size)
        self.n_epochs = int(n_epochs)
        self.learning_rate = float(learning_rate)
        self.gamma = float(gamma)
        self.gae_lambda = float(gae_lambda)
        self.clip_range = float(clip_range)
        self.ent_coef = float(ent_coef)
        self.vf_coef = float(vf_coef)
        self.max_grad_norm = float(max_grad_norm)
        self.embed_size = int(embed_size)
        self.features_dim = int(features_dim)
        self.net_arch = [int(w) for w in net_arch]
        self.eval_episodes = int(eval_episodes)
        self.eval_max_steps = int(eval_max_steps)
        self.eval_deterministic = bool(eval_deterministic)
        self.seed = int(seed)
        self.device = str(device)
        self.torch_threads = int(torch_threads)
        self.progress_bar = bool(progress_bar)
        self.verbose = int(verbose)

    def to_dict(self) -> dict[str, Any]:
        """The constructor arguments (written to sb3_config.json)."""
        return dict(vars(self))

    def build(self, venv) -> Any:
        """SB3 PPO over `venv` (an `SB3VecEnv`) with the Deep Sets extractor."""
        with requires_extra("sb3"):
            from stable_baselines3 import PPO

        native = venv.env
        policy_kwargs = {
            "features_extractor_class": DeepSetsExtractor,
            "features_extractor_kwargs": {
                "layout": asdict(native.layout),
                "embed_size": self.embed_size,
                "features_dim": self.features_dim,
            },
            "net_arch": {"pi": list(self.net_arch), "vf": list(self.net_arch)},
        }
        rollout = self.n_steps * venv.num_envs
        return PPO(
            "MlpPolicy",
            venv,
            n_steps=self.n_steps,
            batch_size=min(self.batch_size, rollout),  # SB3 needs batch <= rollout
            n_epochs=self.n_epochs,
            learning_rate=self.learning_rate,
            gamma=self.gamma,
            gae_lambda=self.gae_lambda,
            clip_range=self.clip_range,
            ent_coef=self.ent_coef,
            vf_coef=self.vf_coef,
            max_grad_norm=self.max_grad_norm,
            policy_kwargs=policy_kwargs,
            seed=self.seed,
            device=self.device,
            verbose=self.verbose,
        )

    def run(self, env, cfg: Any, run_dir: str | Path, logger: Any = None) -> dict[str, Any]:
        """Train on the native `env`, save the model and the evaluation to `run_dir`.

        Args:
            env: A `selfplaydrive.sim.VecEnv` (any action table: SB3 handles both).
            cfg: The composed config (unused beyond what Hydra already wrote to the folder).
            run_dir: Run folder (created).
            logger: Where SB3's scalars go: a logger factory or config node as for
                `trainers.run.train_run` (`instantiate(cfg.logger)`); None: TensorBoard in
                `run_dir/tb`. Its progress bar stays off (`progress_bar` is SB3's own bar).

        Returns:
            {"agent_steps", "model_path", "eval": summary dict (empty when eval_episodes = 0)}.
        """
        with requires_extra("sb3"):
            from stable_baselines3.common.logger import HumanOutputFormat
            from stable_baselines3.common.logger import Logger as SB3Logger

        from selfplaydrive.env import SB3VecEnv
        from selfplaydrive.trainers.run import eval_protocol, make_logger, write_summary

        run_dir = Path(run_dir)
        run_dir.mkdir(parents=True, exist_ok=True)
        if self.torch_threads:
            torch.set_num_threads(self.torch_threads)
        _write_json(run_dir / "sb3_config.json", self.to_dict())
        venv = SB3VecEnv(env, seed=self.seed)
        model = self.build(venv)
        rollouts = math.ceil(self.total_timesteps / (self.n_steps * venv.num_envs))
        log = make_logger(logger)(
            run_dir=run_dir, total_updates=rollouts, progress_bar=False, enabled=True, initial=0
        )
        formats: list[KVWriter] = [LoggerWriter(log)]
        if self.verbose:
            formats.append(HumanOutputFormat(sys.stdout))  # SB3's rollout/train tables
        model.set_logger(SB3Logger(str(run_dir), formats))
        callback = EpisodeMetricsCallback(env)
        try:
            model.learn(self.total_timesteps, callback=callback, progress_bar=self.progress_bar)
        finally:
            log.close()
        model_path = run_dir / "model.zip"
        model.save(model_path)
        print(f"sb3: {model.num_timesteps} slot-steps, model saved to {model_path}")
        summary: dict[str, object] = {}
        if self.eval_episodes:
            summary = evaluate(
                model,
                venv,
                self.eval_episodes,
                self.eval_max_steps,
                self.eval_deterministic,
                self.seed + EVAL_SEED_OFFSET,
            )
            summary.update(eval_protocol(env, self.eval_deterministic))
            write_summary(run_dir, summary)
        return {"agent_steps": int(model.num_timesteps), "model_path": str(model_path), "eval": summary}


def evaluate(model, venv, episodes: int, max_steps: int, deterministic: bool, seed: int) -> dict[str, float]:
    """Run `model` on fresh worlds until every world finished its share of `episodes`
    world-episodes (its first ones, `eval.sampling`) or `max_steps` env steps.

    Returns:
        `trainers.ppo.episodes.summarize` of the finished episodes: waypoint_completion,
        collision_rate, offroad_rate, red_light_rate, return_mean, term/<name>, ... (a dict with
        only agent_episodes when no world finished within `max_steps`).
    """
    native = venv.env
    tracker = EpisodeTracker(native)
    tracker.count_first(episodes)
    venv.seed(seed)
    obs = venv.reset()
    tracker.on_reset()
    records: list[dict[str, object]] = []
    returns: list[float] = []
    for _ in range(max_steps):
        actions, _ = model.predict(obs, deterministic=deterministic)
        obs, _, _, _ = venv.step(actions)
        tracker.on_step(native.reward_mask.copy())
        new_records, new_returns = tracker.pop()
        records += new_records
        returns += new_returns
        if tracker.quota_met:
            break
    return summarize(records, returns)


def _check(name: str, value: Any, ok, expected: str) -> None:
    try:
        good = bool(ok(value))
    except (TypeError, ValueError):
        good = False
    if not good:
        raise ConfigError(f"trainer.{name}: expected {expected}, got {value!r}")


def _write_json(path: Path, data: Mapping[str, Any]) -> None:
    path.write_text(json.dumps(data, indent=2, sort_keys=True, default=_plain) + "\n")


def _plain(value: Any) -> Any:
    return value.item() if isinstance(value, np.generic) else str(value)
