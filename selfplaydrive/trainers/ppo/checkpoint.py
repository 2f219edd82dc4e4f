"""Checkpoints with exact resume: model, optimiser, RNG states (torch, numpy, env), counters,
the env's full simulation state and the trainer's per-slot recurrent state.

Resuming from a checkpoint continues training as if it had never stopped: on the CPU the
parameters after M more updates are bit-identical to an uninterrupted run (tests/trainers/
test_resume.py). The env's state is every buffer of `VecEnv.buffers`, the per-world NumPy
generators and the pending Python-side state; the spawner must draw its randomness only from
the generator it is handed (DESIGN.md principle 7), or expose `state_dict`/`load_state_dict`.
"""

from __future__ import annotations

import copy
import os
import random
from pathlib import Path

import numpy as np
import torch

FORMAT_VERSION = 1
_ENV_PY_ATTRS = ("_seed", "_pending_first", "episode_stats", "_extra_sums")


def env_state(env) -> dict[str, object]:
    """Everything needed to continue `env` (a `VecEnv`) exactly where it is.

    Raises:
        TypeError: When `env` lacks the `VecEnv` attributes this relies on.
    """
    for attr in ("buffers", "_world_rngs"):
        if not hasattr(env, attr):
            raise TypeError(
                f"env: expected a selfplaydrive VecEnv with attribute {attr!r}, got {type(env).__name__}"
            )
    state: dict[str, object] = {
        "buffers": {k: v.copy() for k, v in env.buffers.items()},
        "extra_terms": env.extra_terms.copy(),
        "reward_mask": env.reward_mask.copy(),
        "world_rngs": [g.bit_generator.state for g in env._world_rngs],
        "py": {a: copy.deepcopy(getattr(env, a)) for a in _ENV_PY_ATTRS if hasattr(env, a)},
    }
    if hasattr(env.spawner, "state_dict"):
        state["spawner"] = env.spawner.state_dict()
    return state


def load_env_state(env, state: dict[str, object]) -> None:
    """Restore `env_state(env)` into an env built with the same maps, spawner and sizes.

    Raises:
        ValueError: When a buffer's shape or dtype differs (another env configuration).
    """
    bufs = state["buffers"]
    if set(bufs) != set(env.buffers):
        raise ValueError(
            f"checkpoint env buffers {sorted(set(bufs) ^ set(env.buffers))} differ from this env's: "
            "expected an env built from the same configuration"
        )
    for name, saved in bufs.items():
        live = env.buffers[name]
        if saved.shape != live.shape or saved.dtype != live.dtype:
            raise ValueError(
                f"checkpoint env buffer {name!r}: shape {saved.shape} dtype {saved.dtype}, this env has "
                f"{live.shape} {live.dtype}: expected an env built from the same configuration"
            )
        np.copyto(live, saved)  # in place: the Cython World keeps pointers to these arrays
    np.copyto(env.extra_terms, state["extra_terms"])
    np.copyto(env.reward_mask, state["reward_mask"])
    if len(state["world_rngs"]) != len(env._world_rngs):
        raise ValueError(
            f"checkpoint has {len(state['world_rngs'])} world generators, this env "
            f"{len(env._world_rngs)}: expected the same num_worlds"
        )
    for g, s in zip(env._world_rngs, state["world_rngs"], strict=True):
        g.bit_generator.state = s
    for attr, value in state["py"].items():
        setattr(env, attr, copy.deepcopy(value))
    if "spawner" in state and hasattr(env.spawner, "load_state_dict"):
        env.spawner.load_state_dict(state["spawner"])


def rng_state() -> dict[str, object]:
    """Global RNG states of torch (CPU and CUDA), NumPy and `random`."""
    out: dict[str, object] = {
        "torch": torch.get_rng_state(),
        "numpy": np.random.get_state(),
        "python": random.getstate(),
    }
    if torch.cuda.is_available():
        out["cuda"] = torch.cuda.get_rng_state_all()
    return out


def set_rng_state(state: dict[str, object]) -> None:
    torch.set_rng_state(state["torch"])
    np.random.set_state(state["numpy"])
    random.setstate(state["python"])
    if "cuda" in state and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(state["cuda"])


def save(path: str | Path, payload: dict[str, object]) -> Path:
    """Write `payload` (plus the format version and global RNG states) atomically: a reader
    never sees a half-written checkpoint."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = dict(payload, format_version=FORMAT_VERSION, rng=rng_state())
    tmp = path.with_suffix(path.suffix + ".tmp")
    torch.save(payload, tmp)
    os.replace(tmp, path)
    return path


def load(path: str | Path, map_location: str | torch.device = "cpu") -> dict[str, object]:
    """Read a checkpoint written by `save`.

    Raises:
        FileNotFoundError: No such file.
        ValueError: Another format version.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"checkpoint {path}: no such file")
    # weights_only=False: the payload holds NumPy arrays and generator states we wrote ourselves
    payload = torch.load(path, map_location=map_location, weights_only=False)
    if payload.get("format_version") != FORMAT_VERSION:
        raise ValueError(
            f"checkpoint {path}: format_version {payload.get('format_version')!r}, expected {FORMAT_VERSION}"
        )
    return payload


def checkpoint_name(update: int, rank: int = 0) -> str:
    """File name of the periodic checkpoint after `update` updates (rank > 0 gets a suffix:
    every rank of a torchrun job keeps its own env state)."""
    return f"ckpt_{update:07d}.pt" if rank == 0 else f"ckpt_{update:07d}.rank{rank}.pt"


def _listed(directory: str | Path, rank: int) -> list[Path]:
    files = Path(directory).glob("ckpt_[0-9]*.pt")
    suffix = ".pt" if rank == 0 else f".rank{rank}.pt"
    return sorted(f for f in files if f.name.endswith(suffix) and (rank or ".rank" not in f.name))


def latest(directory: str | Path, rank: int = 0) -> Path | None:
    """Newest periodic checkpoint of `rank` in `directory`, or None."""
    files = _listed(directory, rank)
    return files[-1] if files else None


def prune(directory: str | Path, keep: int, rank: int = 0) -> None:
    """Delete all but the newest `keep` periodic checkpoints of `rank`."""
    for old in _listed(directory, rank)[:-keep]:
        old.unlink(missing_ok=True)
