"""`train_run`: one training run into a run folder (what `selfplaydrive train` calls).

Run folder layout (rank 0 writes the shared files; every rank its own checkpoints):
    config.json        the `PPOConfig` used
    run_info.json      seed, world size, device, git commit, env and model sizes, versions
    tb/                TensorBoard event files (losses, SPS, returns, reward terms, events/km);
                       with logger=jsonl metrics.jsonl instead, with logger=none nothing
    checkpoints/       ckpt_<update>.pt (periodic, pruned), final.pt
    eval.json          the final evaluation summary (also printed); with eval_fixed_coefficients
                       also under the paper's protocol, key fixed_eval_coefficients
"""

from __future__ import annotations

import json
import math
import platform
import random
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from selfplaydrive._optional import requires_extra
from selfplaydrive.errors import CheckpointError
from selfplaydrive.scenario.protocol import follows_protocol, has_protocol, paper_protocol
from selfplaydrive.trainers.ppo import checkpoint as ckpt
from selfplaydrive.trainers.ppo.config import PPOConfig
from selfplaydrive.trainers.ppo.dist import check_resume_agrees
from selfplaydrive.trainers.ppo.logging import Logger, TensorBoardLogger
from selfplaydrive.trainers.ppo.trainer import PPOTrainer

with requires_extra("torch"):
    import torch
    from torch import nn

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
    resume: bool | str | Path | None = False,
    logger: Callable[..., Logger] | Mapping[str, Any] | None = None,
) -> dict[str, object]:
    """Train `model` on `env` with PPO, writing the run folder; returns the evaluation summary.

    Args:
        env: A `VecEnv` (under torchrun: one per rank; the trainer seeds it `seed + rank`).
        model: A policy model (`selfplaydrive.models`). Its initial weights come from torch's
            global generator when it was built: call `seed_everything(seed)` before building it
            (`selfplaydrive train` does) for a run that repeats exactly.
        config: A `PPOConfig` or a mapping of its fields.
        run_dir: Run folder (created).
        resume: Continue an earlier run (see `resolve_resume`): True or a run folder takes its
            newest checkpoint, a `.pt` path that checkpoint. Training then continues in the
            checkpoint's run folder, whose logger output after the checkpoint is dropped first.
            False or None: a new run in `run_dir`.
        logger: Where scalars go: a factory called with the keyword arguments
            `run_dir, total_updates, progress_bar, enabled, initial` (e.g. `JsonlLogger`, or
            what `instantiate(cfg.logger)` returns for a `logger/` config), or a config node
            with a `_target_` (instantiated as a partial). None: `TensorBoardLogger` into
            `run_dir/tb` (the `logger=tensorboard` default).

    Returns:
        {"updates", "agent_steps", "run_dir", "eval": summary dict (see `write_summary`)}.

    Raises:
        CheckpointError: `resume` names no checkpoint, or an unreadable or foreign one.
    """
    cfg = config if isinstance(config, PPOConfig) else PPOConfig.from_dict(dict(config))
    seed_everything(cfg.seed, cfg.torch_threads)
    invoked_in = Path(run_dir)
    checkpoint, run_dir = None, invoked_in
    trainer = PPOTrainer(env, model, cfg, run_dir)
    if resume:
        checkpoint, run_dir = resolve_resume(resume, invoked_in, trainer.dist.rank)
        trainer.run_dir = run_dir
        ckpt.remove_stale_tmp(checkpoint.parent, trainer.dist.rank)
        trainer.load(checkpoint)
        check_resume_agrees(trainer.update_idx, checkpoint, trainer.dist)
    main = trainer.dist.is_main
    run_dir.mkdir(parents=True, exist_ok=True)
    if main and checkpoint is None:
        _write_json(run_dir / "config.json", cfg.to_dict())
        _write_json(run_dir / "run_info.json", run_info(env, model, trainer))
    elif main:
        _record_resume(run_dir, invoked_in, checkpoint, trainer, cfg)
    logger = make_logger(logger)(
        run_dir=run_dir,
        total_updates=trainer.total_updates,
        progress_bar=cfg.progress_bar,
        enabled=main,
        initial=trainer.update_idx,
    )
    try:
        if checkpoint is not None:
            if hasattr(logger, "truncate"):  # what a stopped attempt logged after the checkpoint
                logger.truncate(trainer.trained_steps)
            logger.text(f"resuming from {checkpoint} at update {trainer.update_idx} in {run_dir}")
        trainer.train(logger=logger)
        trainer.save(run_dir / "checkpoints" / ckpt.final_name(trainer.dist.rank))
        summary: dict[str, object] = {}
        if cfg.eval_episodes:
            summary = final_evaluation(trainer, env, cfg)
            if main:
                write_summary(run_dir, summary, logger)
    finally:
        logger.close()
    return {
        "updates": trainer.update_idx,
        "agent_steps": trainer.agent_steps,
        "run_dir": str(run_dir),
        "eval": summary,
    }


def init_weights(model: nn.Module, source: str | Path, widen: bool = False) -> Path:
    """Load a checkpoint's model weights into `model` to start a new run from them (fine-tuning:
    `selfplaydrive train init_from=...`). Only the weights are taken; the optimiser, the counters,
    the learning-rate schedule and the env start fresh, unlike `resume`.

    Args:
        model: The freshly built model of this run's config.
        source: A `.pt` written by `selfplaydrive train` (full or policy-only), or "pretrained"
            for the shipped policy (`selfplaydrive.pretrained`).
        widen: The checkpoint is a narrower Deep Sets model: copy its units into `model`'s
            sizes, keeping its function (`models.widen`; `init_widen=true`).

    Returns:
        The checkpoint's path.

    Raises:
        CheckpointError: No such file, not a checkpoint, or weights of another model or
            observation/action layout (the message names the file and the mismatch).
    """
    from selfplaydrive.policies import load_checkpoint
    from selfplaydrive.pretrained import resolve_spec

    path = Path(resolve_spec(str(source)))
    weights = load_checkpoint(path)["model"]
    if widen:
        from selfplaydrive.models.widen import widen_deepsets_state

        try:
            weights = widen_deepsets_state(weights, model)
        except CheckpointError as exc:
            raise CheckpointError(str(exc), path) from exc
    try:
        model.load_state_dict(dict(weights))
    except RuntimeError as exc:  # missing keys or size mismatches: another model or layout
        first = str(exc).strip().splitlines()
        raise CheckpointError(
            f"its weights do not fit this run's {type(model).__name__} ({' '.join(first[:3])}); expected a "
            "checkpoint of the same model and observation/action layout (repeat the env and model overrides "
            "it was trained with)",
            path,
        ) from exc
    return path


def seed_everything(seed: int, torch_threads: int = 0) -> None:
    """Seed torch (CPU and CUDA), NumPy's and Python's global generators with `seed`: call it
    before building the model, whose initial weights come from torch's global generator.

    Args:
        seed: The run's seed.
        torch_threads: When > 0, torch's CPU thread count is set first (`PPOConfig.torch_threads`).
            The initial weights do not depend on it (`models.common.orthogonal_` runs the QR
            decomposition on one thread), the training's float rounding does.
    """
    if torch_threads:
        torch.set_num_threads(int(torch_threads))
    torch.manual_seed(int(seed))  # also seeds every CUDA device
    np.random.seed(int(seed) % 2**32)
    random.seed(int(seed))


def resolve_resume(resume: bool | str | Path, run_dir: str | Path, rank: int = 0) -> tuple[Path, Path]:
    """The checkpoint and the run folder a `resume` argument of `train_run` names.

    Args:
        resume: True: the newest checkpoint of `run_dir`. A folder: a run folder (or its
            `checkpoints/` folder), its newest checkpoint (`checkpoint.newest`: the furthest of
            the periodic ones and `final.pt`). A file: that checkpoint; rank r > 0 of a torchrun
            job reads its own sibling file (`ckpt_X.rank<r>.pt`, `final.rank<r>.pt`).
        run_dir: The folder of this invocation (used with True, or for a loose checkpoint file).
        rank: This process's rank.

    Returns:
        (checkpoint file, run folder that training continues in: the folder holding the
        checkpoint's `checkpoints/`, else `run_dir`).

    Raises:
        CheckpointError: No such file or folder, or a folder without checkpoints.
    """
    path = Path(run_dir) if resume is True else Path(resume).expanduser()
    if path.is_dir():
        # a run folder, or its checkpoints/ folder itself
        folder = (
            path
            if path.name == "checkpoints" and not (path / "checkpoints").is_dir()
            else path / "checkpoints"
        )
        found = ckpt.newest(folder, rank) if folder.is_dir() else None
        if found is None:
            raise CheckpointError(
                f"resume: no checkpoint (ckpt_*.pt or final.pt) in {folder}: expected the folder of a "
                "run of selfplaydrive train, or a checkpoint file",
                path,
            )
        return found, folder.parent
    if not path.is_file():
        raise CheckpointError(
            "resume: no such file or folder: expected a run folder or a checkpoint .pt", path
        )
    if rank:
        path = path.with_name(ckpt.rank_name(path.name, rank))
    owner = path.parent.parent if path.parent.name == "checkpoints" else Path(run_dir)
    return path, owner


def final_evaluation(trainer: PPOTrainer, env, cfg: PPOConfig) -> dict[str, object]:
    """The end-of-training evaluation: `cfg.eval_episodes` world episodes under the env's own
    coefficient draws and, with `cfg.eval_fixed_coefficients`, again from the same seed under the
    paper's evaluation protocol (`scenario.protocol.paper_protocol`), nested under the key
    "fixed_eval_coefficients" (skipped for a spawner without a conditioning sampler, and for one
    that already follows that protocol: `reward=eval` without curricula). Each summary records
    its protocol (`eval_protocol`) and its vehicle collisions by kind (`collision_kinds`,
    `eval.collisions`)."""
    seed = cfg.seed + EVAL_SEED_OFFSET + trainer.dist.rank
    args = (cfg.eval_episodes, cfg.eval_max_steps, cfg.eval_deterministic, seed)
    summary = _evaluate(trainer, env, args)
    summary.update(eval_protocol(env, cfg.eval_deterministic))
    spawner = getattr(env, "spawner", None)
    if cfg.eval_fixed_coefficients and has_protocol(spawner) and not follows_protocol(spawner):
        with paper_protocol(spawner):  # evaluate() resets every world inside the block
            fixed = _evaluate(trainer, env, args)
            fixed.update(eval_protocol(env, cfg.eval_deterministic))
        summary["fixed_eval_coefficients"] = fixed
    return summary


def _evaluate(trainer: PPOTrainer, env, args: tuple[int, int, bool, int]) -> dict[str, object]:
    from selfplaydrive.eval.collisions import CollisionRecorder

    collisions = CollisionRecorder(env)
    summary: dict[str, object] = dict(trainer.evaluate(*args, recorders=[collisions]))
    summary["collision_kinds"] = collisions.breakdown().to_dict()
    return summary


def eval_protocol(env, deterministic: bool) -> dict[str, str]:
    """How the final evaluation chose its reward coefficients and actions (recorded in eval.json).

    `PPOTrainer.evaluate` runs on the training env, so the coefficients are those of the env's
    spawner: "fixed_eval_coefficients" when it follows the paper's protocol (section 5: every
    penalty at its maximum, B = 0, D = 3 m, training curricula off; `reward=eval`), otherwise
    "training_distribution" (the worlds drawn as in training: coefficients per agent, or
    curricula on). Not the protocol of `selfplaydrive eval`, which builds its own scenarios.
    """
    fixed = follows_protocol(getattr(env, "spawner", None))
    return {
        "protocol": "fixed_eval_coefficients" if fixed else "training_distribution",
        "actions": "greedy" if deterministic else "sampled",
    }


def _record_resume(
    run_dir: Path, invoked_in: Path, checkpoint: Path, trainer: PPOTrainer, cfg: PPOConfig
) -> None:
    """Note a resume in the run folder (`resumes.jsonl`) and, when this invocation has a folder
    of its own (a new Hydra run folder), there too (`resume.json`)."""
    record = {
        "checkpoint": str(checkpoint),
        "update": trainer.update_idx,
        "run_folder": str(run_dir),
        "invoked_in": str(invoked_in),
        "git_commit": _git_commit(),
        "config": cfg.to_dict(),
    }
    with (run_dir / "resumes.jsonl").open("a", encoding="utf-8") as f:
        f.write(json.dumps(record, sort_keys=True, default=str) + "\n")
    if invoked_in.resolve() != run_dir.resolve():
        invoked_in.mkdir(parents=True, exist_ok=True)
        _write_json(invoked_in / "resume.json", record)


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


def write_summary(run_dir: Path, summary: dict[str, object], logger: Logger | None = None) -> None:
    """Print the short evaluation summary (with its protocol, see `eval_protocol`) and save
    every metric to `run_dir/eval.json`."""
    _write_json(run_dir / "eval.json", summary)
    shown = _summary_line(summary)
    how = " ".join(f"{k} {summary[k]}" for k in ("protocol", "actions") if k in summary)
    line = f"evaluation: {shown} ({how or 'protocol not recorded'}; full summary in {run_dir / 'eval.json'})"
    (logger.text if logger is not None else print)(line)
    fixed = summary.get("fixed_eval_coefficients")
    if isinstance(fixed, Mapping):
        how = f"fixed evaluation coefficients, {fixed.get('actions')} actions"
        line = f"evaluation, paper protocol: {_summary_line(fixed)} ({how})"
        (logger.text if logger is not None else print)(line)


def _summary_line(summary: Mapping[str, object]) -> str:
    return ", ".join(
        f"{k} {summary[k]:.3g}" for k in SUMMARY_KEYS if k in summary and math.isfinite(summary[k])
    )


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
    """The checkout's commit, None outside a git checkout (selfplaydrive/runs.py)."""
    from selfplaydrive.runs import git_commit

    commit = git_commit()
    return None if commit == "unknown" else commit


def _write_json(path: Path, data: dict[str, object]) -> None:
    path.write_text(json.dumps(data, indent=2, sort_keys=True, default=str) + "\n")
