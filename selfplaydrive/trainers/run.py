"""`train_run`: one training run into a run folder (what `selfplaydrive train` calls).

Run folder layout (rank 0 writes the shared files; every rank its own checkpoints):
    config.json        the `PPOConfig` used
    run_info.json      seed, world size, device, git commit, env and model sizes, versions
    tb/                TensorBoard event files (losses, SPS, returns, reward terms, events/km);
                       with logger=jsonl metrics.jsonl instead, with logger=none nothing
    checkpoints/       ckpt_<update>.pt (periodic, pruned), final.pt
    eval.json          the final evaluation summary (also printed)
"""

from __future__ import annotations

import json
import math
import platform
import subprocess
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import torch
from torch import nn

from selfplaydrive.trainers.ppo import checkpoint as ckpt
from selfplaydrive.trainers.ppo.config import PPOConfig
from selfplaydrive.trainers.ppo.logging import Logger, TensorBoardLogger
from selfplaydrive.trainers.ppo.trainer import PPOTrainer

EVAL_SEED_OFFSET = 1_000_003  # evaluation episodes never reuse the training seed's worlds
SUMMARY_KEYS = (
    "episodes",
    "agent_episodes",
    "waypoint_completion",
    "collision_rate",
    "offroad_rate",
    "red_light_rate",
    "return_mean",
    "km",
)


def train_run(
    env,
    model: nn.Module,
    config: PPOConfig | dict,
    run_dir: str | Path,
    resume: bool | str | Path = False,
    logger: Callable[..., Logger] | Mapping[str, Any] | None = None,
) -> dict[str, object]:
    """Train `model` on `env` with PPO, writing the run folder; returns the evaluation summary.

    Args:
        env: A `VecEnv` (under torchrun: one per rank; the trainer seeds it `seed + rank`).
        model: A policy model (`selfplaydrive.models`).
        config: A `PPOConfig` or a mapping of its fields.
        run_dir: Run folder (created).
        resume: True continues from the newest checkpoint in `run_dir/checkpoints` (an error
            when there is none); a path continues from that checkpoint.
        logger: Where scalars go: a factory called with the keyword arguments
            `run_dir, total_updates, progress_bar, enabled, initial` (e.g. `JsonlLogger`, or
            what `instantiate(cfg.logger)` returns for a `logger/` config), or a config node
            with a `_target_` (instantiated as a partial). None: `TensorBoardLogger` into
            `run_dir/tb` (the `logger=tensorboard` default).

    Returns:
        {"updates", "agent_steps", "eval": summary dict (see `write_summary`)}.
    """
    cfg = config if isinstance(config, PPOConfig) else PPOConfig.from_dict(dict(config))
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    trainer = PPOTrainer(env, model, cfg, run_dir)
    main = trainer.dist.is_main
    if resume:
        path = _resume_path(run_dir, resume, trainer.dist.rank)
        trainer.load(path)
    elif main:
        _write_json(run_dir / "config.json", cfg.to_dict())
        _write_json(run_dir / "run_info.json", run_info(env, model, trainer))
    logger = make_logger(logger)(
        run_dir=run_dir,
        total_updates=trainer.total_updates,
        progress_bar=cfg.progress_bar,
        enabled=main,
        initial=trainer.update_idx,
    )
    try:
        trainer.train(logger=logger)
        final = run_dir / "checkpoints" / ("final.pt" if main else f"final.rank{trainer.dist.rank}.pt")
        trainer.save(final)
        summary = {}
        if cfg.eval_episodes:
            seed = cfg.seed + EVAL_SEED_OFFSET + trainer.dist.rank
            summary = trainer.evaluate(cfg.eval_episodes, cfg.eval_max_steps, cfg.eval_deterministic, seed)
            if main:
                write_summary(run_dir, summary, logger)
    finally:
        logger.close()
    return {"updates": trainer.update_idx, "agent_steps": trainer.agent_steps, "eval": summary}


def make_logger(spec: Callable[..., Logger] | Mapping[str, Any] | None) -> Callable[..., Logger]:
    """The logger factory of `train_run`'s `logger` argument (see there)."""
    if spec is None:
        return TensorBoardLogger
    if isinstance(spec, Mapping):  # a dict or DictConfig node
        from selfplaydrive.builder import instantiate

        return instantiate(spec, _partial_=True)
    if not callable(spec):
        raise TypeError(
            f"logger: expected a logger factory, a config node with _target_ or None, got {spec!r}"
        )
    return spec


def _resume_path(run_dir: Path, resume: bool | str | Path, rank: int) -> Path:
    if resume is True:
        path = ckpt.latest(run_dir / "checkpoints", rank)
        if path is None:
            raise FileNotFoundError(f"resume=True: no checkpoint ckpt_*.pt in {run_dir / 'checkpoints'}")
        return path
    return Path(resume)


def write_summary(run_dir: Path, summary: dict[str, float], logger: Logger | None = None) -> None:
    """Print the short evaluation summary and save every metric to `run_dir/eval.json`."""
    _write_json(run_dir / "eval.json", summary)
    shown = ", ".join(
        f"{k} {summary[k]:.3g}" for k in SUMMARY_KEYS if k in summary and math.isfinite(summary[k])
    )
    line = f"evaluation: {shown} (full summary in {run_dir / 'eval.json'})"
    (logger.text if logger is not None else print)(line)


def run_info(env, model: nn.Module, trainer: PPOTrainer) -> dict[str, object]:
    """Facts that make the run reproducible and comparable."""
    return {
        "seed": trainer.config.seed,
        "world_size": trainer.dist.world_size,
        "device": str(trainer.device),
        "precision": str(trainer.amp_dtype or "float32"),
        "git_commit": _git_commit(),
        "num_worlds": env.num_worlds,
        "agent_slots": env.num_agents,
        "obs_dim": env.layout.obs_dim,
        "action_nvec": list(trainer.nvec),
        "model": type(model).__name__,
        "parameters": sum(p.numel() for p in model.parameters()),
        "total_updates": trainer.total_updates,
        "torch": torch.__version__,
        "python": platform.python_version(),
    }


def _git_commit() -> str | None:
    try:
        out = subprocess.run(
            ["git", "rev-parse", "HEAD"],
            cwd=Path(__file__).resolve().parent,
            capture_output=True,
            text=True,
            timeout=5,
            check=False,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() or None


def _write_json(path: Path, data: dict[str, object]) -> None:
    path.write_text(json.dumps(data, indent=2, sort_keys=True, default=str) + "\n")
