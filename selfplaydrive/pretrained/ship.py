"""Write a training run's policy into `selfplaydrive/pretrained/` (issue #16 item 3).

    python -m selfplaydrive.pretrained.ship <run>/checkpoints/ckpt_0009000.pt --info info.json

copies the run's `resolved_config.yaml`, writes the policy-only checkpoint (`main_job.pt`:
format version, weights, `model_spec`, PPO settings and counters) and `main_job.json` (the
`--info` facts: command, seed, start and end, machine; the checkpoint's update and steps; the
layout signature of the env built from the copied config).
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from selfplaydrive._optional import requires_extra
from selfplaydrive.errors import CheckpointError
from selfplaydrive.pretrained import CHECKPOINT, FOLDER, METADATA, RUN_CONFIG, build_env, layout_signature


def policy_payload(payload: dict[str, Any], run_config: Any) -> dict[str, Any]:
    """The keys of a training checkpoint that acting needs (`checkpoint.POLICY_KEYS` and what
    rebuilds the model), with the model's constructor arguments from the run's `model` node.

    Args:
        payload: A training checkpoint (`checkpoint.load`).
        run_config: The run's config (`policies.load_run_config`).
    """
    from omegaconf import OmegaConf

    spec = OmegaConf.to_container(run_config.model, resolve=True)
    assert isinstance(spec, dict)
    return {
        "format_version": payload["format_version"],
        "model": payload["model"],
        "model_spec": {k: v for k, v in spec.items() if k not in ("layout", "action_nvec")},
        "config": payload.get("config"),
        "counters": payload.get("counters"),
    }


def ship(checkpoint: str | Path, info: dict[str, Any], out: Path = FOLDER) -> dict[str, Any]:
    """Write the policy of `checkpoint` (in `<run>/checkpoints/`) and its metadata into `out`.

    Args:
        checkpoint: A checkpoint of a `selfplaydrive train` run.
        info: Facts about the training recorded as they are (command, seed, times, machine).
        out: Destination folder (the package's `pretrained/` by default).

    Returns:
        The metadata written to `main_job.json`.

    Raises:
        CheckpointError: No run config next to the checkpoint, or an unreadable checkpoint.
    """
    with requires_extra("torch"):
        import torch

        from selfplaydrive.trainers.ppo import checkpoint as ckpt
    from selfplaydrive.policies import find_run_config, load_run_config

    checkpoint = Path(checkpoint)
    cfg_file = find_run_config(checkpoint)
    if cfg_file is None:
        raise CheckpointError(
            "no resolved_config.yaml in its run folder; expected a training run's checkpoint"
        )
    payload = ckpt.load(checkpoint, required=ckpt.POLICY_KEYS)  # a training checkpoint or a soup
    out.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(cfg_file, out / RUN_CONFIG)
    torch.save(policy_payload(payload, load_run_config(cfg_file)), out / CHECKPOINT)
    counters: dict[str, Any] = dict(payload.get("counters") or {})  # type: ignore[call-overload]
    meta = {
        **info,
        "source_checkpoint": str(checkpoint),
        "update": counters.get("update"),
        "slot_steps": counters.get("global_step"),
        "agent_steps": counters.get("agent_steps"),
        "layout": layout_signature(build_env(num_worlds=1, folder=out)),
        "size_bytes": (out / CHECKPOINT).stat().st_size,
    }
    (out / METADATA).write_text(json.dumps(meta, indent=2) + "\n")
    return meta


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: `python -m selfplaydrive.pretrained.ship CHECKPOINT [--info FILE] [--out DIR]`."""
    parser = argparse.ArgumentParser(prog="python -m selfplaydrive.pretrained.ship", description=__doc__)
    parser.add_argument("checkpoint", help="<run>/checkpoints/<name>.pt")
    parser.add_argument("--info", help="JSON file with the training facts (command, seed, times, machine)")
    parser.add_argument("--out", default=str(FOLDER), help="destination folder (default: the package's)")
    args = parser.parse_args(argv)
    info = json.loads(Path(args.info).read_text()) if args.info else {}
    meta = ship(args.checkpoint, info, Path(args.out))
    print(json.dumps(meta, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
