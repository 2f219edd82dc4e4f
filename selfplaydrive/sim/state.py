"""Save and restore a `VecEnv` rollout: the format behind `VecEnv.get_state` / `set_state`.

A state is a flat dict of NumPy arrays and Python scalars (so `np.savez(path, **state)` and
`torch.save` both take it as it is), with these fields:

    version: int, `STATE_VERSION`.
    num_worlds, agents_per_world: int, the sizes of the env that wrote it.
    map_names: (num maps,) str, the env's maps in order; term_names: (M,) str, its reward
        columns (a reward of the same width but other terms would otherwise pass unnoticed).
    seed: int, the seed `reset(None)` continues from (-1: none, fresh entropy).
    buffers.<name>: every buffer of `VecEnv.buffers` (positions, lights, pedestrians, the
        per-world kernel RNG keys and counters, step counters, episode sums, observations ...).
    reward_mask: (N,) bool, the agents that acted at the last step.
    rng.pcg64: (W, 4) uint64, per world the PCG64 state and increment of the generator the
        spawner draws from at autoreset (high and low 64 bits of each 128-bit number).
    rng.has_uint32: (W,) bool and rng.uinteger: (W,) uint32, its buffered half-word.
    episode_stats.<key>: the finished-episode records not yet popped (`pop_episode_stats`),
        one row per record: world, map, num_agents, spawn_shortfall (n,) int64; length_s, km
        (n,) float64; terms (n, M) float64 (columns `term_names`); events (n, E) int64
        (columns `EVENT_NAMES`); agents_with (n, 4) int64 (columns `EVER_BITS`).
    dropped_episode_stats: int.
    reset_pending: bool, the first scenario is drawn but `reset` not called yet; then the
        fields `pending.<name>` hold that `Scenario`'s fields.

Everything else the env holds is fixed by its constructor arguments: restore into an env built
from the same configuration. A spawner must draw its randomness only from the generator it is
handed (`Spawner`, scenario/base.py); Python reward terms and observation hooks that keep their
own state between steps are not covered.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from selfplaydrive.rewards.registry import EVENT_NAMES
from selfplaydrive.scenario.types import Scenario
from selfplaydrive.sim.buffers import check_scenario

if TYPE_CHECKING:
    from selfplaydrive.sim.vec_env import VecEnv

STATE_VERSION = 1
_SAME_CONFIG = "expected an env built from the same configuration"
_MASK64 = (1 << 64) - 1
# the scalar fields of a finished-episode record (`VecEnv._record_episodes`), in its key order
_STAT_SCALARS = {
    "world": np.int64,
    "map": np.int64,
    "length_s": np.float64,
    "num_agents": np.int64,
    "spawn_shortfall": np.int64,
    "km": np.float64,
}
_STAT_GROUPS = {"terms": np.float64, "events": np.int64, "agents_with": np.int64}
_SCALARS = ("version", "num_worlds", "agents_per_world", "seed", "dropped_episode_stats", "reset_pending")


def get_state(env: VecEnv) -> dict[str, Any]:
    """Copy of everything that changes while `env` runs (the module docstring lists it)."""
    state: dict[str, Any] = {
        "version": STATE_VERSION,
        "num_worlds": int(env.num_worlds),
        "agents_per_world": int(env.agents_per_world),
        "map_names": _names(env)["map_names"],
        "term_names": _names(env)["term_names"],
        "seed": -1 if env._seed is None else int(env._seed),
        "dropped_episode_stats": int(env.dropped_episode_stats),
        "reward_mask": env.reward_mask.copy(),
    }
    state.update({f"buffers.{name}": a.copy() for name, a in env.buffers.items()})
    state.update(encode_generators([g.bit_generator.state for g in env._world_rngs]))
    state.update(encode_episode_stats(env.episode_stats, stat_columns(env)))
    state.update(encode_pending(env._pending_first))
    return state


def set_state(env: VecEnv, state: Mapping[str, Any]) -> None:
    """Restore `get_state`'s output (or `np.load` of it saved by `np.savez`) into `env`; the
    env is left unchanged when this raises.

    Raises:
        ValueError: Not a state dict, another version, or a field missing, unknown or of
            another shape or dtype than this env's (the message names the field).
    """
    if not isinstance(state, Mapping) or "version" not in state:
        raise ValueError(
            "state: expected the dict of VecEnv.get_state() (with a 'version' field), "
            f"got {type(state).__name__}"
        )
    # np.load gives 0-d arrays for the scalars of a state saved with np.savez
    state = {k: v.item() if isinstance(v, np.ndarray) and v.ndim == 0 else v for k, v in state.items()}
    state = _fill_empty_fields(state, _spec(env))
    pending = _validate(env, state)
    for name, live in env.buffers.items():
        np.copyto(live, state[f"buffers.{name}"])  # in place: the Cython World points at these
    np.copyto(env.reward_mask, state["reward_mask"])
    for g, s in zip(env._world_rngs, decode_generators(state), strict=True):
        g.bit_generator.state = s
    seed = int(state["seed"])
    env._seed = None if seed < 0 else seed
    env.episode_stats = decode_episode_stats(state, stat_columns(env))
    env.dropped_episode_stats = int(state["dropped_episode_stats"])
    env._pending_first = pending


# encoding -----------------------------------------------------------------------------------
def encode_generators(states: Sequence[Mapping[str, Any]]) -> dict[str, np.ndarray]:
    """The `rng.*` fields from `Generator.bit_generator.state` dicts (PCG64, `default_rng`).

    Raises:
        ValueError: A generator other than PCG64.
    """
    for w, s in enumerate(states):
        if s["bit_generator"] != "PCG64":
            raise ValueError(f"world {w}: generator {s['bit_generator']!r}, expected PCG64 (default_rng)")
    words = [_split(s["state"]["state"]) + _split(s["state"]["inc"]) for s in states]
    return {
        "rng.pcg64": np.array(words, dtype=np.uint64).reshape(len(states), 4),
        "rng.has_uint32": np.array([bool(s["has_uint32"]) for s in states], dtype=bool),
        "rng.uinteger": np.array([int(s["uinteger"]) for s in states], dtype=np.uint32),
    }


def decode_generators(state: Mapping[str, Any]) -> list[dict[str, Any]]:
    """`bit_generator.state` dicts of the worlds' generators from the `rng.*` fields."""
    out = []
    for words, has, half in zip(
        state["rng.pcg64"], state["rng.has_uint32"], state["rng.uinteger"], strict=True
    ):
        hi, lo, inc_hi, inc_lo = (int(v) for v in words)
        out.append(
            {
                "bit_generator": "PCG64",
                "state": {"state": hi << 64 | lo, "inc": inc_hi << 64 | inc_lo},
                "has_uint32": int(has),
                "uinteger": int(half),
            }
        )
    return out


def _split(value: int) -> list[int]:
    return [value >> 64, value & _MASK64]


def encode_episode_stats(
    records: Sequence[Mapping[str, Any]], columns: Mapping[str, Sequence[str]]
) -> dict[str, np.ndarray]:
    """The `episode_stats.*` fields: one row per record, one column per named value.

    Args:
        records: Finished-episode records as `VecEnv.pop_episode_stats` returns them.
        columns: The names inside each nested dict (terms, events, agents_with), in order.

    Raises:
        ValueError: A record with other keys (the record layout changed without this).
    """
    keys = [*_STAT_SCALARS, *_STAT_GROUPS]
    for r in records:
        if list(r) != keys or any(list(r[g]) != list(columns[g]) for g in _STAT_GROUPS):
            raise ValueError(f"episode record with keys {list(r)}: expected {keys} (sim/state.py)")
    out = {f"episode_stats.{k}": np.array([r[k] for r in records], dtype=t) for k, t in _STAT_SCALARS.items()}
    for g, t in _STAT_GROUPS.items():
        rows = [[r[g][c] for c in columns[g]] for r in records]
        out[f"episode_stats.{g}"] = np.array(rows, dtype=t).reshape(len(records), len(columns[g]))
    return out


def decode_episode_stats(
    state: Mapping[str, Any], columns: Mapping[str, Sequence[str]]
) -> list[dict[str, Any]]:
    """The records of `encode_episode_stats`, with the same keys, order and Python types."""
    n = len(state["episode_stats.world"])
    records: list[dict[str, Any]] = []
    for i in range(n):
        rec: dict[str, Any] = {k: state[f"episode_stats.{k}"][i].item() for k in _STAT_SCALARS}
        for g in _STAT_GROUPS:
            row = state[f"episode_stats.{g}"][i]
            rec[g] = {c: row[j].item() for j, c in enumerate(columns[g])}
        records.append(rec)
    return records


def _names(env: VecEnv) -> dict[str, np.ndarray]:
    """The env's map names and reward column names as str arrays (state fields)."""
    maps = [m.name for m in env.maps]
    return {"map_names": np.array(maps, dtype=str), "term_names": np.array(list(env.term_names), dtype=str)}


def stat_columns(env: VecEnv) -> dict[str, Sequence[str]]:
    """The column names of the nested values of `env`'s episode records."""
    from selfplaydrive.sim.vec_env import EVER_BITS  # vec_env imports this module when used

    return {"terms": list(env.term_names), "events": EVENT_NAMES, "agents_with": list(EVER_BITS)}


def encode_pending(scenario: Scenario | None) -> dict[str, Any]:
    """`reset_pending` and the `pending.*` fields of the scenario drawn for the first reset."""
    out: dict[str, Any] = {"reset_pending": scenario is not None}
    if scenario is not None:
        for f in dataclasses.fields(scenario):
            v = getattr(scenario, f.name)
            out[f"pending.{f.name}"] = v.copy() if isinstance(v, np.ndarray) else v
    return out


# validation ---------------------------------------------------------------------------------
def _validate(env: VecEnv, state: Mapping[str, Any]) -> Scenario | None:
    """Check every field of `state` against `env`; returns the pending first scenario."""
    if state["version"] != STATE_VERSION:
        raise ValueError(
            f"state field 'version': {state['version']!r}, this selfplaydrive reads {STATE_VERSION}"
        )
    for key in ("num_worlds", "agents_per_world"):
        live = getattr(env, key)
        if key in state and state[key] != live:
            raise ValueError(f"state field {key!r}: {state[key]!r}, this env has {live}: {_SAME_CONFIG}")
    for key, live_names in _names(env).items():
        saved = state.get(key)
        if saved is not None and (not isinstance(saved, np.ndarray) or saved.tolist() != live_names.tolist()):
            shown = saved.tolist() if isinstance(saved, np.ndarray) else saved
            raise ValueError(
                f"state field {key!r}: {shown!r}, this env has {live_names.tolist()!r}: {_SAME_CONFIG}"
            )
    spec = _spec(env)
    pending_keys = {k for k in state if k.startswith("pending.")}
    missing = sorted(set(spec) - set(state))
    unknown = sorted(set(state) - set(spec) - pending_keys)
    if missing or unknown:
        raise ValueError(f"state: missing field(s) {missing}, unknown field(s) {unknown}: {_SAME_CONFIG}")
    for key, expected in spec.items():
        _check_field(key, state[key], expected)
    _check_stats(state)
    return _pending(env, state, pending_keys)


def _spec(env: VecEnv) -> dict[str, tuple[tuple[int | None, ...], np.dtype] | type]:
    """Field -> (shape, dtype) for arrays (None: any length) or the Python type of a scalar."""
    W, N = env.num_worlds, env.num_agents
    spec: dict[str, Any] = dict.fromkeys(_SCALARS, int)
    spec["reset_pending"] = bool
    spec.update({k: (v.shape, v.dtype) for k, v in _names(env).items()})  # values checked above
    spec.update({f"buffers.{n}": (a.shape, a.dtype) for n, a in env.buffers.items()})
    spec["reward_mask"] = ((N,), np.dtype(bool))
    spec["rng.pcg64"] = ((W, 4), np.dtype(np.uint64))
    spec["rng.has_uint32"] = ((W,), np.dtype(bool))
    spec["rng.uinteger"] = ((W,), np.dtype(np.uint32))
    spec.update({f"episode_stats.{k}": ((None,), np.dtype(t)) for k, t in _STAT_SCALARS.items()})
    cols = stat_columns(env)
    spec.update({f"episode_stats.{g}": ((None, len(cols[g])), np.dtype(t)) for g, t in _STAT_GROUPS.items()})
    return spec


def _check_field(key: str, value: object, expected: tuple[tuple[int | None, ...], np.dtype] | type) -> None:
    if isinstance(expected, type):
        ok = isinstance(value, (expected, np.bool_ if expected is bool else np.integer))
        if not ok or (expected is int and isinstance(value, (bool, np.bool_))):
            raise ValueError(f"state field {key!r}: expected a {expected.__name__}, got {value!r}")
        return
    shape, dtype = expected
    if not isinstance(value, np.ndarray):
        raise ValueError(f"state field {key!r}: expected a NumPy array, got {type(value).__name__}")
    fits = value.ndim == len(shape) and all(
        s is None or s == v for s, v in zip(shape, value.shape, strict=True)
    )
    if not fits or value.dtype != dtype:
        want = (
            "("
            + ", ".join("n" if s is None else str(s) for s in shape)
            + ("," if len(shape) == 1 else "")
            + ")"
        )
        raise ValueError(
            f"state field {key!r}: shape {value.shape} dtype {value.dtype}, this env has {want} {dtype}: "
            f"{_SAME_CONFIG}"
        )


def _check_stats(state: Mapping[str, Any]) -> None:
    lengths = {k: len(v) for k, v in state.items() if k.startswith("episode_stats.")}
    if len(set(lengths.values())) > 1:
        raise ValueError(
            f"state fields episode_stats.*: expected one row per record in each, got lengths {lengths}"
        )


def _pending(env: VecEnv, state: Mapping[str, Any], keys: set[str]) -> Scenario | None:
    """The `Scenario` of the `pending.*` fields (checked like a spawner's), or None."""
    if not state["reset_pending"]:
        if keys:
            raise ValueError(f"state fields {sorted(keys)}: given while 'reset_pending' is False")
        return None
    names = [f.name for f in dataclasses.fields(Scenario)]
    missing = sorted(f"pending.{n}" for n in names if f"pending.{n}" not in keys)
    unknown = sorted(k for k in keys if k.removeprefix("pending.") not in names)
    if missing or unknown:
        raise ValueError(
            f"state: missing field(s) {missing}, unknown field(s) {unknown} of the pending scenario"
        )
    # copies: the env must not share arrays with the caller's dict
    fields = {n: state[f"pending.{n}"] for n in names}
    sc = Scenario(**{n: v.copy() if isinstance(v, np.ndarray) else v for n, v in fields.items()})
    try:
        check_scenario(sc, env.dims, len(env.maps))
    except ValueError as exc:
        raise ValueError(f"state fields pending.*: {exc}") from exc
    return sc


def _fill_empty_fields(state: Mapping[str, Any], spec: Mapping[str, Any]) -> Mapping[str, Any]:
    """States saved before a buffer existed lack it; a buffer that holds nothing in this env
    (e.g. `buffers.phys_state` of a model without its own state: (N, 0)) is filled in empty, so
    those states and the checkpoints holding them still restore."""
    out = None
    for key, expected in spec.items():
        if key in state or not isinstance(expected, tuple):
            continue
        shape, dtype = expected
        if key.startswith("buffers.") and None not in shape and 0 in shape:
            out = dict(state) if out is None else out
            out[key] = np.zeros(shape, dtype=dtype)
    return state if out is None else out
