"""Checkpoints with exact resume: model, optimiser, RNG states (torch, numpy, env), counters,
the env's full simulation state and the trainer's per-slot recurrent state.

Resuming from a checkpoint continues training as if it had never stopped: on the CPU the
parameters after M more updates are bit-identical to an uninterrupted run (tests/trainers/
test_resume.py). The env's state is `VecEnv.get_state()` (sim/state.py: buffers, per-world
generators, pending statistics); the spawner must draw its randomness only from the generator
it is handed (DESIGN.md principle 7). Format 1 checkpoints (the env's attributes pickled as
they were) still load. `pending_rollout` says whether the counters include a rollout that the
saved state has not collected yet (one in flight under `overlap_collection`, whose actor
weights are saved as `actor`): the collecting side's entries are those from before it, and a
resume collects it again without counting it twice (tests/trainers/test_overlap.py).
"""

from __future__ import annotations

import os
import random
import re
from pathlib import Path

import numpy as np

from selfplaydrive._optional import requires_extra
from selfplaydrive.errors import CheckpointError

with requires_extra("torch"):
    import torch

# 2: the env entry is `VecEnv.get_state()`; 1: the env's attributes as they were (still read)
FORMAT_VERSION = 2
READABLE_VERSIONS = (1, 2)
# what every checkpoint of `PPOTrainer.state_dict` holds; a .pt without them is foreign
REQUIRED_KEYS = frozenset({"format_version", "model", "optimizer", "counters", "env"})
# what acting needs (eval, render, a shipped policy): the weights; a training checkpoint has more
POLICY_KEYS = frozenset({"format_version", "model"})


def env_state(env) -> dict[str, object]:
    """Everything needed to continue `env` (a `VecEnv`) exactly where it is: `env.get_state()`.

    Raises:
        TypeError: When `env` has no `get_state` (not a selfplaydrive `VecEnv`).
    """
    if not callable(getattr(env, "get_state", None)):
        raise TypeError(f"env: expected a selfplaydrive VecEnv (with get_state), got {type(env).__name__}")
    return env.get_state()


def load_env_state(env, state: dict[str, object]) -> None:
    """Restore `env_state(env)` (or the env entry of a format 1 checkpoint) into an env built
    with the same maps, spawner and sizes.

    Raises:
        ValueError: When a field's shape or dtype differs (another env configuration), naming it.
    """
    if "version" not in state and "buffers" in state:
        state = _env_state_from_v1(env, state)
    env.set_state(state)


def _env_state_from_v1(env, old: dict[str, object]) -> dict[str, object]:
    """The `VecEnv.get_state` form of a format 1 env entry: buffers, `extra_terms` (a view of
    the `terms` buffer, so already in it), `reward_mask`, the generators' state dicts and the
    attributes `_seed`, `_pending_first` (a `Scenario` or None) and `episode_stats`."""
    from selfplaydrive.sim import state as fmt

    py: dict = old.get("py", {})  # type: ignore[assignment]
    seed = py.get("_seed")
    state: dict[str, object] = {
        "version": fmt.STATE_VERSION,
        # format 1 kept no sizes: the buffer shapes are checked against this env instead
        "num_worlds": env.num_worlds,
        "agents_per_world": env.agents_per_world,
        "map_names": np.array([m.name for m in env.maps], dtype=str),
        "term_names": np.array(list(env.term_names), dtype=str),
        "seed": -1 if seed is None else int(seed),
        "dropped_episode_stats": int(py.get("dropped_episode_stats", 0)),
        "reward_mask": old["reward_mask"],
    }
    state.update({f"buffers.{k}": v for k, v in old["buffers"].items()})  # type: ignore[attr-defined]
    rngs: list = old["world_rngs"]  # type: ignore[assignment]
    if len(rngs) != env.num_worlds:
        raise ValueError(
            f"checkpoint has {len(rngs)} world generators, this env {env.num_worlds}: "
            "expected the same num_worlds"
        )
    state.update(fmt.encode_generators(rngs))
    state.update(fmt.encode_episode_stats(py.get("episode_stats", []), fmt.stat_columns(env)))
    state.update(fmt.encode_pending(py.get("_pending_first")))
    return state


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


def save(path: str | Path, payload: dict[str, object], rank: int = 0) -> Path:
    """Write `payload` (plus the format version and global RNG states) atomically: a reader
    never sees a half-written checkpoint.

    The file is written as `<path>.tmp` and renamed; `*.tmp` files of `rank` left in the folder
    by a writer that was killed are deleted first.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_tmp(path.parent, rank)
    payload = dict(payload, format_version=FORMAT_VERSION, rng=rng_state())
    tmp = path.with_suffix(path.suffix + ".tmp")
    torch.save(payload, tmp)
    os.replace(tmp, path)
    return path


def remove_stale_tmp(directory: str | Path, rank: int = 0) -> list[Path]:
    """Delete the `*.pt.tmp` files of `rank` in `directory` (a checkpoint writer that was killed
    leaves one behind); returns the deleted paths.

    Only `rank`'s own files go: under torchrun the other ranks may be writing theirs right now.
    """
    removed = []
    for tmp in Path(directory).glob("*.pt.tmp"):
        if _rank_of(tmp.name.removesuffix(".tmp")) == rank:
            tmp.unlink(missing_ok=True)
            removed.append(tmp)
    return removed


def _rank_of(name: str) -> int:
    """The rank a checkpoint file name belongs to (`ckpt_0000050.rank2.pt` -> 2, else 0)."""
    stem = name.removesuffix(".pt")
    _, dot, suffix = stem.rpartition(".rank")
    return int(suffix) if dot and suffix.isdigit() else 0


def safe_globals() -> list[object]:
    """What a checkpoint may contain beyond tensors and plain Python containers: NumPy arrays
    (env buffers, generator states), bytes, and the env's `Scenario` drawn for its next reset
    (a dataclass of arrays). `load` unpickles nothing else."""
    from selfplaydrive.scenario.types import Scenario

    core = getattr(np, "_core", None) or np.core  # NumPy 2 renamed np.core to np._core
    dtype_classes = {type(np.dtype(c)) for c in "?bBhHiIlLqQefdgFDGSUVOMm"}
    return [
        np.ndarray,
        np.dtype,
        core.multiarray._reconstruct,
        core.multiarray.scalar,
        bytes,
        Scenario,
        *sorted(dtype_classes, key=lambda c: c.__name__),
    ]


def load(
    path: str | Path, map_location: str | torch.device = "cpu", required: frozenset[str] = REQUIRED_KEYS
) -> dict[str, object]:
    """Read a checkpoint written by `save`, unpickling only the types of `safe_globals()`
    (`torch.load(weights_only=True)`): a foreign `.pt` cannot run code.

    Args:
        path: The `.pt` file.
        map_location: Torch device of the loaded tensors.
        required: Keys the payload must hold: `REQUIRED_KEYS` to resume training,
            `POLICY_KEYS` to act (a policy-only file holds the weights and its config).

    Raises:
        CheckpointError: No such file, not a torch file, a pickle with other types, a file
            without our keys, or another format version (one line naming the file).
    """
    path = Path(path)
    if not path.is_file():
        raise CheckpointError("no such file: expected a checkpoint written by selfplaydrive train", path)
    try:
        with torch.serialization.safe_globals(safe_globals()):
            payload = torch.load(path, map_location=map_location, weights_only=True)
    except Exception as exc:  # torch raises UnpicklingError, RuntimeError, EOFError ... on bad files
        raise CheckpointError(f"cannot read the checkpoint: {_describe_load_error(exc)}", path) from exc
    missing = sorted(required - set(payload)) if isinstance(payload, dict) else sorted(required)
    if missing:
        raise CheckpointError(
            f"not a selfplaydrive checkpoint: a {type(payload).__name__} without the key(s) {missing}", path
        )
    if payload["format_version"] not in READABLE_VERSIONS:
        raise CheckpointError(
            f"format_version {payload['format_version']!r}, expected one of {READABLE_VERSIONS} (this "
            "selfplaydrive reads those; a newer one needs a newer selfplaydrive)",
            path,
        )
    return payload


def _describe_load_error(exc: BaseException) -> str:
    """One line on why `torch.load` refused a file (torch's own message spans many lines)."""
    text = str(exc)
    found = re.search(r"GLOBAL (\S+) was not an allowed global", text)
    if found:
        return f"it refers to {found.group(1)}, which a selfplaydrive checkpoint never contains"
    if isinstance(exc, EOFError):
        return "the file is empty or cut short"
    found = re.search(r"WeightsUnpickler error:\s*(.+?)(?:\n\n|$)", text, re.DOTALL)
    detail = " ".join((found.group(1) if found else text).split())[:160]
    return f"not a torch checkpoint file ({type(exc).__name__}: {detail})"


def checkpoint_name(update: int, rank: int = 0) -> str:
    """File name of the periodic checkpoint after `update` updates (rank > 0 gets a suffix:
    every rank of a torchrun job keeps its own env state)."""
    return f"ckpt_{update:07d}.pt" if rank == 0 else f"ckpt_{update:07d}.rank{rank}.pt"


def final_name(rank: int = 0) -> str:
    """File name of the checkpoint written after the last update (`train_run`)."""
    return "final.pt" if rank == 0 else f"final.rank{rank}.pt"


def rank_name(name: str, rank: int) -> str:
    """The name rank `rank` gives the checkpoint file `name` (`ckpt_0000050.pt` ->
    `ckpt_0000050.rank2.pt` for rank 2; rank 0 drops a rank suffix)."""
    stem = re.sub(r"\.rank\d+$", "", name.removesuffix(".pt"))
    return f"{stem}.pt" if rank == 0 else f"{stem}.rank{rank}.pt"


def update_of(path: str | Path) -> int:
    """Updates done when the checkpoint at `path` was written (reads the file).

    Raises:
        CheckpointError: As `load`.
    """
    return int(load(path)["counters"]["update"])


def newest(directory: str | Path, rank: int = 0) -> Path | None:
    """The checkpoint of `rank` in `directory` that is furthest into training: the newest
    periodic one, or `final.pt` when it is at least as far (a resumed run that was stopped
    early leaves a `final.pt` older than its periodic checkpoints). None when there is none."""
    periodic = latest(directory, rank)
    final = Path(directory) / final_name(rank)
    if not final.is_file():
        return periodic
    if periodic is None or update_of(final) >= int(re.match(r"ckpt_(\d+)", periodic.name).group(1)):
        return final
    return periodic


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
