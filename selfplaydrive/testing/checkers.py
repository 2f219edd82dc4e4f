"""Shipped checkers of components (DESIGN.md principle 8; docs/components.md "Test a component").

`check_reward_term` and `check_spawner` run a component the way the env does and raise
`ComponentCheckError` (an `AssertionError`, so pytest reports it as a failed check) naming the
component and what failed: the output's shape or finiteness, determinism at 1 and 2 threads,
writes outside the component's own outputs, or an invalid scenario. Both return None when
every check passes, so a test of your own component is one line:

    check_reward_term(SpeedLimit())
    check_spawner(MySpawner(), road_map)
"""

from __future__ import annotations

import dataclasses
import pickle
import random
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

import numpy as np

from selfplaydrive.rewards.base import MapBoundTerm, RewardHook
from selfplaydrive.scenario.base import Spawner
from selfplaydrive.sim.actions import BoxActions

if TYPE_CHECKING:
    from selfplaydrive.maps.roadmap import RoadMap
    from selfplaydrive.physics.base import PhysicsModel
    from selfplaydrive.rewards.components import KernelTerm
    from selfplaydrive.scenario.types import Scenario
    from selfplaydrive.sim.vec_env import VecEnv

__all__ = ["ComponentCheckError", "check_reward_term", "check_spawner"]

# buffers a reward term writes (its column, the reward sum, the per-world episode sums); every
# other buffer must come out as without the term
_REWARD_OUTPUTS = ("terms", "term_sum", "reward")


class ComponentCheckError(AssertionError):
    """A component broke its contract; the message names the component and the check."""


# reward terms ------------------------------------------------------------------------------
def check_reward_term(
    term: KernelTerm | RewardHook | MapBoundTerm,
    road_map: RoadMap | None = None,
    spawner: Spawner | None = None,
    steps: int = 30,
    seed: int = 0,
    num_worlds: int = 2,
    physics: PhysicsModel | None = None,
) -> None:
    """Check a reward term of either form (compiled `KernelTerm` or Python `RewardHook`).

    Steps three envs in lockstep on the same random rollout: the paper's eight terms alone (1
    thread) and with `term` appended at weight 1 (1 and 2 threads). Checked at every step: the
    term's column is finite for the agents that acted and of shape (N,); with 1 and 2 threads it
    is the same bit for bit; and every buffer other than the reward outputs (its column, the
    reward sum, the episode sums, the reward-term state a term with state owns) and the other
    terms' columns equal those of the env without the term (a term writes nothing else). A
    map-bound term (rewards/base.py `MapBoundTerm`) is bound to `road_map` by the envs.

    Args:
        term: The term.
        road_map: Map of the rollout (default: the bundled town).
        spawner: Spawner of the rollout (default: a small `PaperSpawner` with 2 s episodes, so
            autoresets happen within `steps`).
        steps, seed, num_worlds: The rollout.
        physics: Physics model of the envs (default: the env's, `FrictionBicycleModel`).

    Raises:
        ComponentCheckError: Naming the term and the first failed check (step, agent slot).
    """
    from selfplaydrive.rewards.components import KernelTerm, _is_map_bound

    if not isinstance(term, (KernelTerm, RewardHook)) and not _is_map_bound(term):
        raise ComponentCheckError(
            f"reward term {term!r}: expected a KernelTerm or a RewardHook (name and __call__(state)), "
            "or a map-bound term (bind(maps))"
        )
    form = term.form if isinstance(term, KernelTerm) else "map-bound" if _is_map_bound(term) else "python"
    label = f"reward term {term.name!r} ({form})"
    road_map = road_map if road_map is not None else _default_map()
    spawner = spawner if spawner is not None else _small_spawner()
    envs = [
        _reward_env(label, road_map, spawner, physics, None, num_worlds, seed, 1),
        _reward_env(label, road_map, spawner, physics, term, num_worlds, seed, 1),
        _reward_env(label, road_map, spawner, physics, term, num_worlds, seed, 2),
    ]
    ref, one, two = envs
    for k, acts in enumerate(_actions(ref, steps, seed)):
        for env in envs:
            _step(label, env, acts, k)
        col = one.reward_terms[:, -1]
        bad = ~np.isfinite(col) & one.reward_mask
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise ComponentCheckError(
                f"{label}: step {k}: wrote {col[i]} for agent slot {i}, expected finite"
            )
        other = two.reward_terms[:, -1]
        if not _equal(col, other):
            i = int(np.flatnonzero(col.view(np.uint32) != other.view(np.uint32))[0])
            raise ComponentCheckError(
                f"{label}: step {k}: nondeterministic: agent slot {i} got {col[i]} with 1 thread and "
                f"{other[i]} with 2 (same seed and actions)"
            )
        _same_buffers(label, one, two, k, "nondeterministic: with 1 and 2 threads (same seed) it differs")
        _same_outside(label, ref, one, k)


def _reward_env(
    label: str,
    road_map: RoadMap,
    spawner: Spawner,
    physics: PhysicsModel | None,
    term: Any,
    num_worlds: int,
    seed: int,
    threads: int,
) -> VecEnv:
    from selfplaydrive.rewards.components import LinearReward
    from selfplaydrive.rewards.registry import TERM_NAMES
    from selfplaydrive.sim.vec_env import VecEnv

    weights = dict.fromkeys(TERM_NAMES, 1.0)
    if term is None:
        reward = LinearReward(weights)
    else:
        if term.name in weights:
            raise ComponentCheckError(f"{label}: named like a paper term; check it under another name")
        reward = LinearReward({**weights, term.name: 1.0}, terms=[term])
    env = VecEnv(
        road_map, spawner, num_worlds, physics=_any(physics), seed=seed, num_threads=threads, reward=reward
    )
    try:
        env.reset(seed)
    except ValueError as exc:
        raise ComponentCheckError(f"{label}: at reset: {exc}") from exc
    return env


def _step(label: str, env: VecEnv, acts: np.ndarray, k: int) -> None:
    try:
        env.step(acts)
    except ValueError as exc:
        # VecEnv's own checks (shape, finiteness) and NumPy's read-only views raise ValueError
        why = "wrote to its input (the state views are read-only)" if "read-only" in str(exc) else exc
        raise ComponentCheckError(f"{label}: step {k}: {why}") from exc


def _same_outside(label: str, ref: VecEnv, env: VecEnv, k: int) -> None:
    """Every buffer equal to the env without the term, but the reward sum and the term's own
    column (the last) of the per-term buffers."""
    for name, a in ref.buffers.items():
        if name in ("reward", "term_state"):  # term_state: a term's own per-agent memory
            continue
        b = env.buffers[name]
        if name in _REWARD_OUTPUTS:
            b = b[:, : a.shape[1]]
        if not _equal(a, b):
            i = _first_difference(a, b)
            where = "the other terms' columns" if name in _REWARD_OUTPUTS else f"buffer {name!r}"
            raise ComponentCheckError(
                f"{label}: step {k}: wrote outside its column: {where} differs from the env without "
                f"the term at index {i}"
            )


def _same_buffers(label: str, a: VecEnv, b: VecEnv, k: int, what: str) -> None:
    for name, x in a.buffers.items():
        if not _equal(x, b.buffers[name]):
            i = _first_difference(x, b.buffers[name])
            raise ComponentCheckError(f"{label}: step {k}: {what}: buffer {name!r} at index {i}")


# spawners ----------------------------------------------------------------------------------
def check_spawner(
    spawner: Spawner,
    road_map: RoadMap,
    samples: int = 8,
    seed: int = 0,
    steps: int = 20,
    physics: PhysicsModel | None = None,
) -> None:
    """Check a spawner (`Spawner`: ``sample(road_map, rng, map_index=0) -> Scenario``).

    Checked: every sample is a `Scenario` with the documented dtypes and the same slot counts
    as the first; it passes the env's scenario checks (counts within the slots, finite
    positions, positive sizes, positive episode length: `sim.buffers.check_scenario`); no two
    valid vehicles (agents, static vehicles) overlap; `map_index` is kept; the same generator
    state gives the same scenario, also after other samples (no hidden state); it draws from no
    global generator (NumPy's, `random`'s) and leaves the map unchanged; an env built on it
    runs the same at 1 and 2 threads.

    Args:
        spawner: The spawner.
        road_map: The map to sample on.
        samples: Scenarios drawn (seeds `seed`, `seed + 1`, ...).
        seed: First seed.
        steps: Env steps of the 1-versus-2-threads run (0: skip it).
        physics: Physics model of that run (default: the env's).

    Raises:
        ComponentCheckError: Naming the spawner and the first failed check.
    """
    label = f"spawner {type(spawner).__name__}"
    if not isinstance(spawner, Spawner):
        raise ComponentCheckError(f"{label}: expected a sample(road_map, rng, map_index=0) method")
    before = _map_digest(road_map)
    global_state = _global_digest()
    first = _sample(label, spawner, road_map, seed, 0)
    for k in range(samples):
        sc = first if k == 0 else _sample(label, spawner, road_map, seed + k, k % 2)
        _check_one(label, sc, first, road_map, seed + k)
    again = _sample(label, spawner, road_map, seed, 0)
    for f, a, b in _fields(first, again):
        if not _equal(a, b):
            raise ComponentCheckError(
                f"{label}: not deterministic: the same generator state gave another scenario.{f} "
                "(every draw must come from the generator it is handed, and no state kept between calls)"
            )
    if _global_digest() != global_state:
        raise ComponentCheckError(f"{label}: drew from a global generator (numpy.random or random)")
    if _map_digest(road_map) != before:
        raise ComponentCheckError(f"{label}: changed the road map it was handed")
    if steps > 0:
        _check_threads(label, spawner, road_map, seed, steps, physics)


def _sample(label: str, spawner: Spawner, road_map: RoadMap, seed: int, map_index: int) -> Scenario:
    from selfplaydrive.scenario.types import Scenario

    try:
        sc = spawner.sample(road_map, np.random.default_rng(seed), map_index=map_index)
    except Exception as exc:  # a third-party component may raise anything: name it
        raise ComponentCheckError(f"{label}: sample(seed={seed}) raised {type(exc).__name__}: {exc}") from exc
    if not isinstance(sc, Scenario):
        raise ComponentCheckError(
            f"{label}: sample(seed={seed}) returned {type(sc).__name__}, expected a Scenario"
        )
    if sc.map_index != map_index:
        raise ComponentCheckError(
            f"{label}: sample(seed={seed}, map_index={map_index}) returned map_index={sc.map_index}"
        )
    return sc


def _check_one(label: str, sc: Scenario, first: Scenario, road_map: RoadMap, seed: int) -> None:
    from selfplaydrive.sim.buffers import Dims, check_scenario

    ref = _empty_like(first, road_map)
    for f, a, b in _fields(sc, ref):
        if isinstance(b, np.ndarray) and (np.asarray(a).dtype != b.dtype or np.shape(a) != b.shape):
            raise ComponentCheckError(
                f"{label}: seed {seed}: scenario.{f} is {np.asarray(a).dtype} {np.shape(a)}, expected "
                f"{b.dtype} {b.shape} (the slot counts of the first sample)"
            )
    G = max(1, road_map.num_signal_groups)
    try:
        check_scenario(sc, Dims.of(sc, 1, G, 1, 1, 1, 1), 2)
    except ValueError as exc:
        raise ComponentCheckError(f"{label}: seed {seed}: {exc}") from exc
    pair = _overlapping_vehicles(sc)
    if pair is not None:
        raise ComponentCheckError(
            f"{label}: seed {seed}: vehicles {pair[0]} and {pair[1]} overlap at the start"
        )


def _empty_like(sc: Scenario, road_map: RoadMap) -> Scenario:
    from selfplaydrive.scenario.types import Scenario

    return Scenario.empty(
        len(sc.agent_valid),
        int(np.shape(sc.waypoints)[1]),
        len(sc.static_valid),
        len(sc.ped_valid),
        int(np.shape(sc.ped_path)[1]),
        len(sc.light_state),
    )


def _overlapping_vehicles(sc: Scenario) -> tuple[str, str] | None:
    """The first pair of valid vehicles (agents, static vehicles) whose boxes overlap."""
    from selfplaydrive.eval.waymax_metrics import pairwise_overlap

    names = [f"agent {i}" for i in range(len(sc.agent_valid))]
    names += [f"static {i}" for i in range(len(sc.static_valid))]
    valid = np.concatenate([sc.agent_valid, sc.static_valid]).astype(bool)
    boxes = np.column_stack(
        [
            np.concatenate([sc.agent_xy, sc.static_xy]),
            np.concatenate([sc.agent_length, sc.static_length]),
            np.concatenate([sc.agent_width, sc.static_width]),
            np.concatenate([sc.agent_heading, sc.static_heading]),
        ]
    ).astype(np.float64)[valid]
    if len(boxes) < 2:
        return None
    hits = np.argwhere(np.triu(pairwise_overlap(boxes)))
    if not len(hits):
        return None
    idx = np.flatnonzero(valid)
    return names[idx[hits[0, 0]]], names[idx[hits[0, 1]]]


def _check_threads(
    label: str, spawner: Spawner, road_map: RoadMap, seed: int, steps: int, physics: PhysicsModel | None
) -> None:
    from selfplaydrive.sim.vec_env import VecEnv

    envs = []
    for threads in (1, 2):
        env = VecEnv(road_map, spawner, 3, physics=_any(physics), seed=seed, num_threads=threads)
        try:
            env.reset(seed)
        except ValueError as exc:
            raise ComponentCheckError(f"{label}: VecEnv.reset refused a scenario: {exc}") from exc
        envs.append(env)
    for k, acts in enumerate(_actions(envs[0], steps, seed)):
        for env in envs:
            env.step(acts)
        _same_buffers(label, envs[0], envs[1], k, "an env on it differs with 1 and 2 threads")


# shared helpers ----------------------------------------------------------------------------
def _any(physics: PhysicsModel | None) -> Any:
    """`physics` for `VecEnv`, whose annotation still names the bicycle models (any
    `PhysicsModel` works: the env reads `kernel_params()` and, if external, `step`)."""
    return physics


def _default_map() -> RoadMap:
    from selfplaydrive.maps.loader import load_map

    return load_map("default")


def _small_spawner() -> Spawner:
    from selfplaydrive.scenario.spawner import PaperSpawner

    return PaperSpawner(num_agents=8, num_static=8, num_pedestrians=2, episode_lengths=(2.0,))


def _actions(env: VecEnv, steps: int, seed: int) -> Iterator[np.ndarray]:
    """Random actions of `env`'s action table, mostly forward (agents move and meet)."""
    rng = np.random.default_rng(seed)
    t = env.action_table
    for _ in range(steps):
        if t.discrete:
            n_acc, n_steer = len(t.accel), len(t.steer)
            yield np.stack(
                [rng.integers(n_acc // 2, n_acc, env.num_agents), rng.integers(0, n_steer, env.num_agents)], 1
            )
        elif isinstance(t, BoxActions) and len(t.low) != 2:
            # a model's own box (e.g. the delta model's dx, dy, dyaw): uniform within its bounds
            yield rng.uniform(t.low, t.high, (env.num_agents, len(t.low))).astype(np.float32)
        else:
            yield np.stack(
                [rng.uniform(-1.0, 2.0, env.num_agents), rng.uniform(-0.3, 0.3, env.num_agents)], 1
            ).astype(np.float32)


def _fields(a: Scenario, b: Scenario) -> Iterator[tuple[str, Any, Any]]:
    for f in dataclasses.fields(a):
        yield f.name, getattr(a, f.name), getattr(b, f.name)


def _equal(a: object, b: object) -> bool:
    """Bit for bit (NaN equals NaN, -0.0 differs from 0.0)."""
    x, y = np.asarray(a), np.asarray(b)
    return x.shape == y.shape and x.dtype == y.dtype and x.tobytes() == y.tobytes()


def _first_difference(a: np.ndarray, b: np.ndarray) -> tuple[int, ...] | str:
    """Index of the first element whose bytes differ."""
    if a.shape != b.shape or a.dtype != b.dtype:
        return f"(shapes {a.shape} and {b.shape}, dtypes {a.dtype} and {b.dtype})"
    x, y = np.ascontiguousarray(a), np.ascontiguousarray(b)
    per = x.dtype.itemsize
    diff = np.flatnonzero(x.reshape(-1).view(np.uint8) != y.reshape(-1).view(np.uint8))
    return tuple(int(v) for v in np.unravel_index(int(diff[0]) // per, a.shape))


def _map_digest(road_map: RoadMap) -> list[bytes]:
    """The bytes of every array reachable through the map's dataclass fields."""
    out: list[bytes] = []

    def walk(obj: object, depth: int) -> None:
        if isinstance(obj, np.ndarray):
            out.append(obj.tobytes())
        elif dataclasses.is_dataclass(obj) and depth < 4:
            for f in dataclasses.fields(obj):
                walk(getattr(obj, f.name), depth + 1)

    walk(road_map, 0)
    return out


def _global_digest() -> bytes:
    """The states of NumPy's and `random`'s global generators, as bytes."""
    return pickle.dumps((np.random.get_state(), random.getstate()))
