"""The pretrained policy shipped with the library (issue #16 item 3; docs/training.md, "The
pretrained policy").

`policy=pretrained` (`selfplaydrive eval`) and `driver=pretrained` / `policy=pretrained`
(`selfplaydrive render`) resolve to the files of this folder:

- `main_job.pt`: a policy-only checkpoint (format version, the model's weights, its
  `model_spec` and the PPO settings; no optimiser and no env state), read by
  `selfplaydrive.policies.load_checkpoint`;
- `resolved_config.yaml`: the config of the training run (observation sizes, action table,
  observation scales, physics, spawner), found by `selfplaydrive.policies.find_run_config` next
  to the checkpoint, so the policy is driven in the env it was trained in;
- `main_job.json`: how it was trained (command, seed, duration, machine, commit) and the
  observation/action layout signature (`layout_signature`) that tests/test_pretrained.py
  compares with the env built from the config today: a change to the observation or action
  layout fails that test until the policy is trained again;
- `REPORT.md` / `report.json`: its evaluation (benchmarks/pretrained_report.py).

This module imports neither torch nor the simulator at import time.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from selfplaydrive.errors import CheckpointError

__all__ = [
    "CHECKPOINT",
    "FOLDER",
    "METADATA",
    "NAME",
    "RUN_CONFIG",
    "build_env",
    "checkpoint_path",
    "evaluation_config",
    "layout_signature",
    "load_metadata",
    "resolve_spec",
]

NAME = "pretrained"
FOLDER = Path(__file__).resolve().parent
CHECKPOINT = "main_job.pt"
RUN_CONFIG = "resolved_config.yaml"
METADATA = "main_job.json"


def checkpoint_path() -> Path:
    """The shipped policy-only checkpoint.

    Raises:
        CheckpointError: The file is missing (an install without the package data).
    """
    path = FOLDER / CHECKPOINT
    if not path.is_file():
        raise CheckpointError(
            "the pretrained policy is missing from this installation; expected the package data "
            f"selfplaydrive/pretrained/{CHECKPOINT} (reinstall selfplaydrive)",
            path,
        )
    return path


def resolve_spec(spec: str | os.PathLike[str]) -> str:
    """`"pretrained"` -> the path of the shipped checkpoint; any other spec unchanged."""
    return str(checkpoint_path()) if str(spec) == NAME else str(spec)


def load_metadata() -> dict[str, Any]:
    """`main_job.json`: training command, seed, duration, machine, commit and layout signature.

    Raises:
        CheckpointError: The file is missing or not JSON.
    """
    path = FOLDER / METADATA
    try:
        return dict(json.loads(path.read_text()))
    except (OSError, ValueError) as exc:
        raise CheckpointError(f"pretrained metadata: expected a JSON file ({exc})", path) from exc


def layout_signature(env: Any) -> dict[str, Any]:
    """What a trained model's weights depend on in `env`: the observation layout (width and
    blocks, paper section 2.5) and the action space (section 2.6), as plain JSON data.

    Args:
        env: A `VecEnv`.

    Returns:
        {"obs_dim", "blocks": {name: shape}, "action_kind", "action_nvec", "accel", "steer_rad"}
        (the last three only for discrete action tables).
    """
    layout, table = env.layout, env.action_table
    sig: dict[str, Any] = {
        "obs_dim": int(layout.obs_dim),
        "blocks": {k: [int(n) for n in shape] for k, shape in layout.blocks().items()},
        "action_kind": type(table).__name__,
    }
    nvec = getattr(env.action_space, "nvec", None)
    if nvec is not None:
        sig["action_nvec"] = [int(n) for n in nvec]
        sig["accel"] = [round(float(v), 6) for v in table.accel]
        sig["steer_rad"] = [round(float(v), 6) for v in table.steer]
    return sig


def build_env(
    num_worlds: int = 1, seed: int = 0, maps: Any = None, folder: Path = FOLDER, **overrides: Any
) -> Any:
    """The env the shipped policy was trained in, built from `resolved_config.yaml` (maps, spawner,
    observation, actions, physics and reward of the training run) with `num_worlds` worlds.

    Args:
        num_worlds: Worlds of the env.
        seed: The env's seed.
        maps: Maps that replace the run's (e.g. Tartu); None: the run's own.
        folder: Where `resolved_config.yaml` lies (the package's folder by default).
        **overrides: Further `VecEnv` arguments (see `selfplaydrive.builder.build_env`).
    """
    from selfplaydrive.builder import build_env as build
    from selfplaydrive.policies import load_run_config

    cfg = load_run_config(Path(folder) / RUN_CONFIG)
    cfg.env.num_worlds, cfg.env.num_threads, cfg.env.seed = int(num_worlds), 1, int(seed)
    if maps is not None:
        overrides["maps"] = maps
    return build(cfg, **overrides)


def evaluation_config(
    map_name: str | None = None,
    agents: int | None = None,
    sizes_from: str | os.PathLike[str] | None = None,
    folder: Path = FOLDER,
) -> Any:
    """The shipped run's config (`resolved_config.yaml`) set up for the paper's evaluation
    protocol (section 5): the fixed evaluation coefficients (`reward.mode: eval`), the training
    curricula of its spawner off (`scenario.spawner.without_curricula`), one env thread.

    Args:
        map_name: A `map` option (default, tartu ...) replacing the run's maps; None keeps them.
        agents: Agents per world (None: the run's).
        sizes_from: A run config whose observation sizes and model replace the shipped run's (a
            candidate checkpoint's own, `policies.find_run_config`); None keeps them.
        folder: Where `resolved_config.yaml` lies (the package's folder by default).
    """
    from selfplaydrive.builder import compose
    from selfplaydrive.policies import load_run_config
    from selfplaydrive.scenario.spawner import without_curricula

    cfg = load_run_config(Path(folder) / RUN_CONFIG)
    if sizes_from is not None:
        own = load_run_config(sizes_from)
        cfg.obs, cfg.model = own.obs, own.model  # e.g. a candidate widened to the paper's sizes
    cfg.reward.mode = "eval"  # conf/reward/eval.yaml: the paper's fixed evaluation coefficients
    if map_name is not None:
        cfg.map = compose("train", [f"map={map_name}"]).map
    cfg.env.num_threads = 1
    if agents is not None:
        cfg.spawner.num_agents = int(agents)
    without_curricula(cfg.spawner)  # turn-lane starts and worlds: training, not the protocol
    return cfg
