"""Average the weights of several fine-tunings of one policy into one policy (a "model soup",
Wortsman et al. 2022): fine-tunings that start from the same weights stay in one basin of the
loss, and their mean is often better than each of them, at no cost when acting.

    python -m selfplaydrive.trainers.soup runs/soup runs/a/checkpoints/final.pt runs/b/checkpoints/final.pt

writes `runs/soup/checkpoints/final.pt` (a policy-only checkpoint: format version, the mean
weights, the first ingredient's PPO settings and the ingredients), `runs/soup/resolved_config.yaml`
(the first ingredient's run config, so `eval`, `render`, `pretrained.ship` and
`benchmarks/select_candidates.py` treat the folder as a run) and `runs/soup/soup.json` (the
ingredients with their SHA-256). The ingredients must read the same observation and act in the
same action table: their run configs' `obs`, `model`, `env.actions` and `env.params` nodes must
agree, and their weights must have the same names, shapes and dtypes.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import shutil
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from selfplaydrive._optional import requires_extra
from selfplaydrive.errors import CheckpointError

# run-config nodes that fix what the weights mean (observation layout and scales, model, actions)
LAYOUT_NODES = ("obs", "model", "env.actions", "env.params")


def average_weights(states: Sequence[dict[str, Any]], names: Sequence[str]) -> dict[str, Any]:
    """The element-wise mean of floating-point tensors; other tensors must be equal.

    Args:
        states: Model state dicts (name -> tensor), at least two.
        names: A label per state dict for the error messages (its file).

    Returns:
        The averaged state dict (float64 accumulation, each tensor back in its own dtype).

    Raises:
        ValueError: Fewer than two state dicts, or one whose names, shapes or dtypes differ from
            the first's, or unequal non-float tensors; the message names the file and the tensor.
    """
    with requires_extra("torch"):
        import torch

    if len(states) < 2:
        raise ValueError(f"a soup needs at least two checkpoints, got {len(states)}")
    first = states[0]
    for state, name in zip(states[1:], names[1:], strict=True):
        if set(state) != set(first):
            extra, missing = sorted(set(state) - set(first)), sorted(set(first) - set(state))
            raise ValueError(
                f"{name}: weights {extra} not in {names[0]}, {missing} missing; expected the same model"
            )
        for key, ref in first.items():
            if state[key].shape != ref.shape or state[key].dtype != ref.dtype:
                raise ValueError(
                    f"{name}: weight {key!r} is {tuple(state[key].shape)} {state[key].dtype}, expected "
                    f"{tuple(ref.shape)} {ref.dtype} as in {names[0]}"
                )
    out = {}
    for key, ref in first.items():
        if ref.is_floating_point():
            total = sum(s[key].to(torch.float64) for s in states)
            out[key] = (total / len(states)).to(ref.dtype)
        else:
            for state, name in zip(states[1:], names[1:], strict=True):
                if not torch.equal(state[key], ref):
                    raise ValueError(f"{name}: integer tensor {key!r} differs from {names[0]}'s")
            out[key] = ref.clone()
    return out


def _node(cfg: Any, dotted: str) -> Any:
    from omegaconf import OmegaConf

    node = OmegaConf.select(cfg, dotted)
    return None if node is None else OmegaConf.to_container(node, resolve=False)


def check_layouts(configs: Sequence[Any], names: Sequence[str]) -> None:
    """Raise ValueError naming the file and the node where a run config's `LAYOUT_NODES`
    differ from the first ingredient's."""
    for cfg, name in zip(configs[1:], names[1:], strict=True):
        for dotted in LAYOUT_NODES:
            if _node(cfg, dotted) != _node(configs[0], dotted):
                raise ValueError(
                    f"{name}: run config node {dotted!r} is {_node(cfg, dotted)}, expected "
                    f"{_node(configs[0], dotted)} as in {names[0]}'s run: the policies must read the same "
                    "observation and act in the same action table"
                )


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def make_soup(checkpoints: Sequence[str | Path], out: str | Path) -> dict[str, Any]:
    """Average `checkpoints` into the run-like folder `out` (see the module docstring).

    Args:
        checkpoints: Checkpoints of `selfplaydrive train` runs (each with its run config) or soups.
        out: Destination folder; `checkpoints/final.pt` there must not exist yet.

    Returns:
        What `soup.json` holds: the ingredients (path, SHA-256, update, slot-steps) and the file.

    Raises:
        CheckpointError: A checkpoint that does not load or has no run config.
        ValueError: Ingredients that do not fit together (`average_weights`, `check_layouts`).
        FileExistsError: `out` already holds a soup.
    """
    with requires_extra("torch"):
        import torch

        from selfplaydrive.trainers.ppo import checkpoint as ckpt
    from selfplaydrive.policies import find_run_config, load_run_config

    paths = [Path(p) for p in checkpoints]
    if len(set(map(str, paths))) != len(paths):
        raise ValueError(f"a checkpoint is named twice: {[str(p) for p in paths]}")
    target = Path(out) / "checkpoints" / "final.pt"
    if target.exists():
        raise FileExistsError(f"{target} exists; a soup is written into a new folder")
    payloads, configs, cfg_files = [], [], []
    for path in paths:
        cfg_file = find_run_config(path)
        if cfg_file is None:
            raise CheckpointError(
                "no resolved_config.yaml in its run folder; expected a run's checkpoint", path
            )
        payloads.append(ckpt.load(path, required=ckpt.POLICY_KEYS))
        configs.append(load_run_config(cfg_file))
        cfg_files.append(cfg_file)
    names = [str(p) for p in paths]
    check_layouts(configs, names)
    weights = average_weights([p["model"] for p in payloads], names)
    ingredients = []
    for path, payload in zip(paths, payloads, strict=True):
        counters: dict[str, Any] = dict(payload.get("counters") or {})  # type: ignore[call-overload]
        ingredients.append(
            {
                "checkpoint": str(path),
                "sha256": _sha256(path),
                "update": counters.get("update"),
                "slot_steps": counters.get("global_step"),
            }
        )
    target.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(cfg_files[0], Path(out) / "resolved_config.yaml")
    payload = {
        "format_version": ckpt.FORMAT_VERSION,
        "model": weights,
        "config": payloads[0].get("config"),
        "counters": None,
        "soup": [i["checkpoint"] for i in ingredients],
    }
    torch.save(payload, target)
    meta = {"ingredients": ingredients, "checkpoint": str(target), "sha256": _sha256(target)}
    (Path(out) / "soup.json").write_text(json.dumps(meta, indent=2) + "\n")
    return meta


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: `python -m selfplaydrive.trainers.soup OUT CHECKPOINT CHECKPOINT [...]`."""
    parser = argparse.ArgumentParser(prog="python -m selfplaydrive.trainers.soup", description=__doc__)
    parser.add_argument("out", help="folder of the soup (a new one)")
    parser.add_argument("checkpoints", nargs="+", help="two or more checkpoints of runs")
    args = parser.parse_args(argv)
    print(json.dumps(make_soup(args.checkpoints, args.out), indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
