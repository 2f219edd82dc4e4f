"""Run folders: what every command writes next to its outputs (DESIGN.md "Hydra": the resolved
config, the git commit and the seed).

Shared by the Hydra entry points (hydra_app.py), evaluation (eval/app.py) and the trainers
(trainers/run.py), so none of them imports another for it.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

__all__ = ["git_commit", "write_run_meta"]


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
    """Write resolved_config.yaml and run_meta.json (commit, seed, overrides) into the folder of
    the current Hydra run (`HydraConfig.get().runtime.output_dir`); returns that folder."""
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
