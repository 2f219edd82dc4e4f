"""Hydra entry points of the CLI: `selfplaydrive train|eval|render|bench` take Hydra overrides
and `-m` multirun. Each run folder gets the resolved config, the git commit and the seed.
"""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from selfplaydrive.builder import CONFIG_MODULE, compose
from selfplaydrive.errors import ConfigError

HYDRA_FLAGS = {"-m", "--multirun", "--cfg", "--resolve", "--info", "-c", "--help", "-h", "--hydra-help"}


def check_overrides(config_name: str, argv: Sequence[str]) -> None:
    """Compose once with the first value of every sweep so that an unknown group option or key
    fails before any run starts, with a `ConfigError` listing the valid choices."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    overrides = [a for a in argv if not a.startswith("-") and "=" in a]
    if not overrides:
        return
    first = []
    for ov in OverridesParser.create().parse_overrides(overrides):
        key = ov.get_key_element()
        if ov.is_sweep_override():
            value = next(iter(ov.sweep_string_iterator()))
        else:
            value = ov.get_value_element_as_str()
        first.append(f"{key}={value}")
    compose(config_name, first)


def git_commit() -> str:
    """The commit of the selfplaydrive checkout ('unknown' outside a git checkout)."""
    root = Path(__file__).resolve().parents[1]
    try:
        out = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True, timeout=10
        )
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return out.stdout.strip() if out.returncode == 0 else "unknown"


def write_run_meta(cfg: Any) -> Path:
    """Write resolved_config.yaml and run_meta.json (commit, seed, overrides) into the run folder."""
    from hydra.core.hydra_config import HydraConfig
    from omegaconf import OmegaConf

    hc = HydraConfig.get()
    run_dir = Path(hc.runtime.output_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "resolved_config.yaml").write_text(OmegaConf.to_yaml(cfg, resolve=True))
    meta = {
        "git_commit": git_commit(),
        "seed": int(cfg.seed),
        "overrides": list(hc.overrides.task),
        "choices": {k: v for k, v in hc.runtime.choices.items() if not k.startswith("hydra")},
        "command": " ".join(sys.argv),
    }
    (run_dir / "run_meta.json").write_text(json.dumps(meta, indent=2))
    return run_dir


def run_hydra(config_name: str, task: Callable[[Any], Any], argv: Sequence[str]) -> int:
    """Run `task(cfg)` under Hydra with `argv` as the override list (supports `-m`)."""
    import hydra

    argv = list(argv)
    try:
        check_overrides(config_name, argv)
    except ConfigError as exc:
        print(f"selfplaydrive {config_name}: error: {exc}", file=sys.stderr)
        return 1

    @hydra.main(config_path=f"pkg://{CONFIG_MODULE}", config_name=config_name, version_base="1.3")
    def _main(cfg: Any) -> Any:
        return task(cfg)

    saved = sys.argv
    sys.argv = [f"selfplaydrive {config_name}", *argv]
    try:
        _main()
    finally:
        sys.argv = saved
    return 0


def train_task(cfg: Any) -> dict[str, Any]:
    """One training run: build env and model from the config, train, evaluate (torch needed)."""
    from selfplaydrive.builder import build_env, build_model, instantiate
    from selfplaydrive.trainers.run import train_run

    run_dir = write_run_meta(cfg)
    env = build_env(cfg)
    trainer = instantiate(cfg.trainer)
    if hasattr(trainer, "run"):  # e.g. the stable-baselines3 path (trainer=sb3) builds its own policy
        return trainer.run(env, cfg, run_dir)
    model = build_model(cfg, env)
    return train_run(env, model, trainer, run_dir)


def cmd_train(argv: Sequence[str]) -> int:
    """``selfplaydrive train [overrides] [-m]``."""
    return run_hydra("train", train_task, argv)


def cmd_eval(argv: Sequence[str]) -> int:
    """``selfplaydrive eval [overrides] [-m]``."""
    from selfplaydrive.eval.app import eval_task

    return run_hydra("eval", eval_task, argv)
