"""`VecEnv`: many driving worlds stepped in one call (paper section 2; spec item 8).

The env composes a list of maps, a spawner (anything with `sample(road_map, rng, map_index)`
returning a `Scenario`), a physics model and an action table; it owns preallocated NumPy
buffers that the Cython kernels (_sim/) read and write, zero copy.

Buffers after `step` (N = num_worlds * agents per world):
    observations (N, obs_dim) float32: next observation of every slot with `masks` set.
    rewards (N,) float32, reward_terms (N, M) float32 (one column per selected reward term,
        named by `term_names`: the paper's eight by default; each column holds weight * term, and
        `rewards` is their sum), extra_terms (N, len(reward_hooks)): the columns of the
        `reward_hooks`, the last ones. Valid where `reward_mask` (the agent acted this step).
    terminations, truncations (N,) bool: the agent's episode ended this step.
    final_observations (N, obs_dim): observation at the end, valid where either flag is set.
    masks (N,) bool: slot holds an active agent that acts at the next step.

Autoreset (same step): a world whose time is up or whose agents have all ended is resampled
from the spawner inside `step`; its rows of `observations` then hold the new episode's first
observations and `final_observations` keep the last ones of the agents that ended.
"""

from __future__ import annotations

import dataclasses
import os
import warnings
from collections.abc import Mapping, Sequence
from types import SimpleNamespace
from typing import Any

import numpy as np

from selfplaydrive._sim.world import STAGES, World, copy_discrete
from selfplaydrive.errors import ConfigError
from selfplaydrive.maps.roadmap import RoadMap
from selfplaydrive.obs.config import ObsConfig, ObsHook
from selfplaydrive.obs.encoders import Encoder, KernelEncoder, as_encoder, bind_encoder
from selfplaydrive.obs.layout import ObsLayout
from selfplaydrive.physics.components import PhysicsModel
from selfplaydrive.physics.models import FrictionBicycleModel
from selfplaydrive.rewards.components import KernelTerm, LinearReward
from selfplaydrive.rewards.registry import EVENT_NAMES, RewardHook
from selfplaydrive.scenario.types import Scenario
from selfplaydrive.sim.actions import BoxActions, DiscreteActions
from selfplaydrive.sim.agent_outcomes import agent_outcomes
from selfplaydrive.sim.atlas import build_atlas
from selfplaydrive.sim.buffers import Dims, allocate, buffer_bytes, check_scenario, pack
from selfplaydrive.sim.params import SimParams
from selfplaydrive.sim.schema import struct_layout

_FAST_ACTION_DTYPES = (np.dtype(np.int32), np.dtype(np.int64))
EVER_BITS = {"collision": 1, "pedestrian_collision": 2, "offroad": 4, "red_light": 8}
# OpenMP threads at most: far more than any useful count (the worlds are split among threads),
# far fewer than the tens of thousands with which libgomp kills the process
MAX_THREADS = max(64, 4 * (os.cpu_count() or 1))
# finished-episode records kept until `pop_episode_stats` (a few kB each): an env stepped
# without popping them keeps the newest ones instead of growing without bound
MAX_EPISODE_STATS = 10_000


class VecEnv:
    """Vectorized multi-agent driving env.

    Args:
        maps: One `RoadMap` or a sequence; worlds draw a map uniformly from their own generator.
        spawner: Object with `sample(road_map, rng, map_index=0) -> Scenario`.
        num_worlds: Worlds stepped together.
        physics: A physics model (default `FrictionBicycleModel()`, section 2.6): a component
            called inside the step (physics/components.py: the library's models, a numba
            cfunc or Cython function as `KernelPhysics`), or one stepped in Python before the
            kernels (`PymunkModel()`, ablations, slow).
        actions: `DiscreteActions()` (default, section 2.4), `ContinuousActions()`, or another
            table or box the physics model reads; default: the model's own action space (e.g.
            `JerkBicycleModel`'s table of changes), else the paper's discrete tables.
        params: `SimParams` (default: the paper's constants).
        obs: The observation encoder (section 2.5; obs/encoders.py): `PaperEncoder` (the
            default: 63 objects, 200 road segments within 100 m), an `ObsConfig` (the paper
            encoder of those sizes), `PartialObsEncoder`, a `KernelEncoder` (numba, Cython) or
            a Python encoder, which replaces the compiled one. `layout` is the encoder's.
        seed: Seed of the first `reset`.
        num_threads: OpenMP threads stepping the worlds (results do not depend on it), at
            most `MAX_THREADS`.
        terminated_vehicle: "remove" or "obstacle" (stays as a static obstacle).
        reward: The reward terms and their weights (`LinearReward`, or its mapping of term name
            to weight; default: the paper's eight terms, weight 1, section 2.3). Compiled terms
            run inside the parallel step, Python terms after it; one column each.
        reward_hooks: Python reward terms appended to `reward` with weight 1.
        obs_hooks: Python observation features appended after the kernel columns.
        profile: Time each stage (slower: one parallel loop per stage).

    Raises:
        ConfigError: `num_worlds`, `num_threads` or `seed` not an integer in range (2.5 is
            refused, not truncated), or buffers for `num_worlds` worlds larger than the
            memory available (the message gives the bytes per world).
        ValueError: Other bad arguments, each naming the argument.
    """

    def __init__(
        self,
        maps: RoadMap | Sequence[RoadMap],
        spawner: object,
        num_worlds: int,
        physics: PhysicsModel | None = None,
        actions: DiscreteActions | BoxActions | None = None,
        params: SimParams | None = None,
        obs: ObsConfig | Encoder | None = None,
        seed: int | None = 0,
        num_threads: int = 1,
        terminated_vehicle: str = "remove",
        reward: LinearReward | Mapping[str, float] | None = None,
        reward_hooks: Sequence[RewardHook] = (),
        obs_hooks: Sequence[ObsHook] = (),
        profile: bool = False,
    ) -> None:
        self.maps = [maps] if isinstance(maps, RoadMap) else list(maps)
        if not self.maps or not all(isinstance(m, RoadMap) for m in self.maps):
            raise ValueError(f"maps: expected a RoadMap or a non-empty sequence of RoadMaps, got {maps!r}")
        if not hasattr(spawner, "sample"):
            raise ValueError(
                f"spawner: expected an object with a sample(road_map, rng, map_index) method, got {spawner!r}"
            )
        num_worlds = check_integer("num_worlds", num_worlds, 1)
        num_threads = check_integer("num_threads", num_threads, 1, MAX_THREADS)
        seed = check_seed(seed)
        if terminated_vehicle not in ("remove", "obstacle"):
            raise ValueError(
                f"terminated_vehicle: expected 'remove' or 'obstacle', got {terminated_vehicle!r}"
            )
        self.spawner = spawner
        self.num_worlds = int(num_worlds)
        # --- physics component (physics/components.py): a kernel model called through its
        # function pointer inside the step, or one stepped in Python (`external`)
        self.physics: Any = physics if physics is not None else FrictionBicycleModel()
        needed = ("physics_slot", "kernel_params", "resolve_actions", "state_dim", "max_speed")
        missing = [n for n in needed if not hasattr(self.physics, n)]
        if missing:
            raise ValueError(
                f"physics: expected a physics model (a selfplaydrive.physics.PhysicsModel), got "
                f"{self.physics!r}, which lacks {missing}"
            )
        self._external_physics = bool(getattr(self.physics, "external", False))
        self.action_table = self.physics.resolve_actions(actions)
        # --- end physics component
        self.params = _with_coeff_scale(params if params is not None else SimParams(), spawner)
        # ---- observation encoder (issue #13) ----
        # the read-only road data of the maps, shared by all worlds; an encoder that needs map
        # data of its own takes it from the maps and the atlas here (obs/encoders.py bind_encoder)
        self.atlas = build_atlas(self.maps, length_scale=self.params.length_scale)
        self.encoder = bind_encoder(as_encoder(obs), self.maps, self.atlas)
        self._kernel_encoder = isinstance(self.encoder, KernelEncoder)
        enc_layout = self.encoder.layout
        road_gather = (
            self.encoder.road_gather
            if isinstance(self.encoder, KernelEncoder)
            else max(enc_layout.max_road, 1)
        )
        # the sizes the kernels see (obs_radius, the road gather), as before the encoders
        self.obs_config = ObsConfig(
            max(enc_layout.max_objects, 1), int(road_gather or 1), float(self.encoder.radius)
        )
        # ---- end observation encoder ----
        self.num_threads = num_threads
        self.terminated_vehicle = terminated_vehicle
        self.reward_hooks = list(reward_hooks)
        # map-bound terms (rules.py: junction zones, stop lines ...) pack this env's maps, and
        # terms with per-agent state get their `term_state` columns (docs/components.md)
        self.reward = _reward(reward).bind(self.maps).with_hooks(self.reward_hooks)
        self.obs_hooks = list(obs_hooks)
        self.profile = bool(profile)
        self.layout = dataclasses.replace(
            enc_layout, extra_dim=enc_layout.extra_dim + sum(int(h.dim) for h in self.obs_hooks)
        )
        self._encoder_dim = enc_layout.obs_dim  # columns the encoder writes (hooks follow)
        self._seed = seed
        # world 0's generator alone first: the first scenario gives the buffer sizes, which
        # are checked against the memory before num_worlds generators are made
        seeds = _world_seeds(seed, self.num_worlds)
        self._world_rngs = [np.random.default_rng(int(seeds[0]))]
        first = self._sample(0)
        G = max([1] + [m.num_signal_groups for m in self.maps])
        p = self.params
        self.dims = Dims.of(
            first,
            self.num_worlds,
            G,
            enc_layout.max_objects,
            self.obs_config.max_road,
            max(p.cand_cap, self.encoder.scratch if isinstance(self.encoder, KernelEncoder) else 0),
            self.layout.obs_dim,
        )
        self.dims = dataclasses.replace(self.dims, num_terms=len(self.reward.columns))
        self.dims = dataclasses.replace(
            self.dims,
            act_dim=int(self.action_table.dim),
            phys_dim=int(self.physics.state_dim),
            term_state_dim=int(self.reward.term_state_dim),
        )
        _check_memory(self.dims)
        self._world_rngs += [np.random.default_rng(int(s)) for s in seeds[1:]]
        self.buffers = allocate(self.dims)
        self._world = World(
            self.dims.__dict__,
            self.buffers,
            struct_layout(),
            self.atlas,
            self._kernel_params(),
            self.reward.plan(),
            self.physics.physics_slot(),
            self.encoder.plan() if isinstance(self.encoder, KernelEncoder) else (0, None),
        )
        self._expose()
        self.episode_stats: list[dict[str, object]] = []
        # per-agent end states in each episode record ("agents", sim/agent_outcomes.py); not
        # carried by get_state
        self.record_agents = False
        self.dropped_episode_stats = 0  # records discarded past MAX_EPISODE_STATS
        self._pending_first = first

    # construction helpers -------------------------------------------------------------------
    def _kernel_params(self) -> dict[str, object]:
        k = self.params.kernel_params()
        k.update(self.physics.kernel_params())
        k["obs_radius"] = self.obs_config.radius
        k["pos_scale"] = self.obs_config.radius
        k["discrete"] = int(self.action_table.discrete)
        k["accel_table"] = np.ascontiguousarray(self.action_table.accel, dtype=np.float32)
        k["steer_table"] = np.ascontiguousarray(self.action_table.steer, dtype=np.float32)
        k["obstacle_mode"] = int(self.terminated_vehicle == "obstacle")
        # the physics model's own parameters (World takes them with its address; listed here so
        # that everything the kernels read is in one place, tests/test_parity_effect.py)
        args = self.physics.physics_slot()[1]
        k["physics_args"] = args if args is not None else np.zeros(0, dtype=np.float32)
        return k

    def _expose(self) -> None:
        b = self.buffers
        self.num_agents = self.dims.W * self.dims.A
        self.agents_per_world = self.dims.A
        # read-only views: the observation stage clears only the padding rows that changed
        # (_sim/observe.pyx), so a write from outside would leave stale rows behind
        self.observations = _read_only(b["obs"])
        self.final_observations = _read_only(b["final_obs"])
        self.rewards = b["reward"]
        self.reward_terms = b["terms"]
        # Python-term columns (filled after the kernels): hooks are the last ones
        self._python_columns = [k for k, c in enumerate(self.reward.columns) if not c.native]
        # user-compiled terms run unchecked inside the step: their output is checked after it
        # (one isfinite over the N rewards); the library's own terms need no check
        self._check_compiled = any(
            isinstance(c.term, KernelTerm) and c.term.form != "builtin" for c in self.reward.columns
        )
        self.extra_terms = b["terms"][:, b["terms"].shape[1] - len(self.reward_hooks) :]
        self.terminations = b["term"].view(bool)
        self.truncations = b["trunc"].view(bool)
        self.masks = b["active"].view(bool)
        self.reward_mask = np.zeros(self.num_agents, dtype=bool)
        self.term_names = self.reward.names
        views = {}
        for name, arr in b.items():
            v = arr.view()
            v.flags.writeable = False
            views[name] = v
        self.state = SimpleNamespace(**views)
        self.observation_space = _box(self.layout)
        self.action_space = self.action_table.space

    def _setup_rngs(self, seed: int | None) -> None:
        self._world_rngs = [np.random.default_rng(int(s)) for s in _world_seeds(seed, self.num_worlds)]

    def _sample(self, w: int):
        rng = self._world_rngs[w]
        m = int(rng.integers(len(self.maps))) if len(self.maps) > 1 else 0
        return self.spawner.sample(self.maps[m], rng, map_index=m)

    # stepping -------------------------------------------------------------------------------
    def reset(self, seed: int | None = None) -> np.ndarray:
        """Start a new episode in every world; same seed, same rollout (any thread count).

        Args:
            seed: Seed of the world generators (a non-negative integer); None continues from
                the last seed.

        Returns:
            The (N, obs_dim) observations buffer.

        Raises:
            ConfigError: `seed` is not a non-negative integer.
        """
        if seed is not None:
            seed = check_seed(seed)
        if seed is not None or self._pending_first is None:
            self._setup_rngs(self._seed if seed is None else seed)
            if seed is not None:
                self._seed = seed
            self._pending_first = self._sample(0)
        self.episode_stats.clear()
        self._reset_worlds(np.arange(self.num_worlds, dtype=np.int32), first=self._pending_first)
        self._pending_first = None
        self.terminations[:] = False
        self.truncations[:] = False
        self.rewards[:] = 0.0
        self.reward_terms[:] = 0.0
        self._run_python_obs(None)
        return self.observations

    def step(self, actions: np.ndarray) -> None:
        """Apply `actions` ((N, D): int indices for discrete, float32 for continuous; D = 2 unless
        the physics model declares other action columns, `action_table.dim`) to every
        agent, step all worlds, autoreset ended worlds. Results are in the env's buffers.

        Raises:
            ValueError: Actions of the wrong type, shape or dtype, out of range or not finite.
        """
        if not self._copy_discrete_fast(actions):
            a = self.action_table.validate(actions, self.num_agents)
            np.copyto(self.buffers["act_i" if self.action_table.discrete else "act_f"], a)
        np.copyto(self.reward_mask, self.masks)
        if self._external_physics:
            t = self.action_table
            self._step_external_physics(self.buffers["act_i" if t.discrete else "act_f"])
        self._world.step(self.num_threads, self.profile)
        if self._check_compiled and not np.isfinite(self.rewards).all():
            self._report_compiled_terms()
        if self._python_columns:
            self._run_python_terms()
        if self.obs_hooks or not self._kernel_encoder:
            self._run_python_obs(self.terminations | self.truncations)
        if not self.buffers["done"].any():
            return  # no per-world Python work on the common path
        done = np.flatnonzero(self.buffers["done"]).astype(np.int32)
        self._record_episodes(done)
        self._reset_worlds(done)
        self._run_python_obs(None)

    def _copy_discrete_fast(self, actions: object) -> bool:
        """Check and copy discrete actions of the usual kinds (C-contiguous int32/int64) in one
        Cython pass (the NumPy checks take ~15 us per step for 1,024 agents). False: the
        caller takes the NumPy path, which also names any bad value."""
        t = self.action_table
        if not (
            t.discrete
            and isinstance(actions, np.ndarray)
            and actions.shape == (self.num_agents, 2)
            and actions.dtype in _FAST_ACTION_DTYPES
            and actions.flags.c_contiguous
        ):
            return False
        return copy_discrete(actions, self.buffers["act_i"], len(t.accel), len(t.steer)) < 0

    def _step_external_physics(self, a: np.ndarray) -> None:
        """Dynamics stepped in Python (e.g. `PymunkModel`) before the kernels, which skip theirs."""
        t = self.action_table
        if t.discrete:
            accel, steer = t.accel[a[:, 0]], t.steer[a[:, 1]]
        else:
            accel, steer = a[:, 0], a[:, 1]
        self.physics.step(self.buffers, self.params.dt, accel, steer)

    def _reset_worlds(self, worlds: np.ndarray, first=None, given: Sequence[Scenario] | None = None) -> None:
        import time

        t0 = time.perf_counter()
        for k, w in enumerate(worlds):
            if given is not None:
                sc = given[k]
            else:
                sc = first if (first is not None and w == 0) else self._sample(int(w))
            check_scenario(sc, self.dims, len(self.maps))
            key = int(self._world_rngs[int(w)].integers(0, 2**63 - 1))
            pack(self.buffers, self.dims, int(w), sc, self.params.dt, key)
        self._world.after_reset(worlds, self.num_threads)
        self._world.timings["reset"] += time.perf_counter() - t0

    def _report_compiled_terms(self) -> None:
        """Raise naming the compiled term that wrote a non-finite value (section 2.3 columns)."""
        bad = ~np.isfinite(self.reward_terms)
        k = int(np.flatnonzero(bad.any(axis=0))[0])
        i = int(np.flatnonzero(bad[:, k])[0])
        col = self.reward.columns[k]
        form = col.term.form if isinstance(col.term, KernelTerm) else "python"
        raise ValueError(
            f"reward term {col.name!r} ({form}): wrote {self.reward_terms[i, k]} for agent slot {i} "
            f"({int(bad[:, k].sum())} non-finite values this step)"
        )

    def _run_python_terms(self) -> None:
        """Columns of the Python reward terms, after the kernels (which zeroed them): weighted,
        added to the reward and to the world's episode sum (section 2.3)."""
        b = self.buffers
        for k in self._python_columns:
            col = self.reward.columns[k]
            term = col.term
            assert isinstance(term, RewardHook)  # _python_columns holds the Python terms
            r = np.asarray(term(self.state), dtype=np.float32)
            if r.shape != (self.num_agents,):
                raise ValueError(
                    f"reward term {col.name!r}: expected an output of shape ({self.num_agents},) "
                    f"(one value per agent slot), got {r.shape}"
                )
            bad = ~np.isfinite(r) & self.reward_mask
            if bad.any():
                i = int(np.flatnonzero(bad)[0])
                raise ValueError(
                    f"reward term {col.name!r}: wrote {r[i]} for agent slot {i} "
                    f"({int(bad.sum())} non-finite values among the agents that acted)"
                )
            r = np.where(self.reward_mask, r * np.float32(col.weight), np.float32(0.0)).astype(np.float32)
            b["terms"][:, k] = r
            self.rewards += r
            b["term_sum"][:, k] += r.reshape(self.num_worlds, self.dims.A).sum(axis=1, dtype=np.float64)

    def _run_python_obs(self, ended: np.ndarray | None) -> None:
        """A Python encoder's rows (it replaces the compiled one), then the hooks' columns, for
        the active slots and, after a step, those that `ended` (their final observations)."""
        rows = self.masks if ended is None else (self.masks | ended)
        if not self._kernel_encoder:
            enc = self.encoder
            assert not isinstance(enc, KernelEncoder)  # _kernel_encoder is False
            d = self._encoder_dim
            f = np.asarray(enc(self.state), dtype=np.float32)
            if f.shape != (self.num_agents, d):
                raise ValueError(
                    f"encoder {enc.name!r}: expected an output of shape ({self.num_agents}, {d}) "
                    f"(layout.obs_dim of {enc.layout}), got {f.shape}"
                )
            bad = ~np.isfinite(f[rows]).all(axis=1)
            if bad.any():
                i = int(np.flatnonzero(rows)[np.flatnonzero(bad)[0]])
                raise ValueError(f"encoder {enc.name!r}: non-finite values in the row of agent slot {i}")
            self.buffers["obs"][rows, :d] = f[rows]
            if ended is not None:
                self.buffers["final_obs"][ended, :d] = f[ended]
        col = self._encoder_dim
        for hook in self.obs_hooks:
            f = np.asarray(hook(self.state), dtype=np.float32)
            if f.shape != (self.num_agents, hook.dim) or not np.all(np.isfinite(f)):
                raise ValueError(
                    f"obs hook {hook.name!r}: expected ({self.num_agents}, {hook.dim}) finite values, "
                    f"got {f.shape}"
                )
            self.buffers["obs"][rows, col : col + hook.dim] = f[rows]
            if ended is not None:
                self.buffers["final_obs"][ended, col : col + hook.dim] = f[ended]
            col += hook.dim

    # statistics -----------------------------------------------------------------------------
    def _record_episodes(self, worlds: np.ndarray) -> None:
        b, A = self.buffers, self.dims.A
        for w in worlds:
            a = slice(w * A, (w + 1) * A)
            ever = b["ever"][a]
            spawned = int(np.count_nonzero(b["agent_valid"][a]))
            terms = {n: float(v) for n, v in zip(self.term_names, b["term_sum"][w], strict=True)}
            rec: dict[str, object] = {
                "world": int(w),
                "map": int(b["map_id"][w]),
                "length_s": float(b["step"][w] * self.params.dt),
                "num_agents": spawned,
                "spawn_shortfall": A - spawned,
                "km": float(b["dist"][w] / 1000.0),
                "terms": terms,
                "events": {n: int(v) for n, v in zip(EVENT_NAMES, b["ev_count"][w], strict=True)},
                "agents_with": {n: int(np.count_nonzero(ever & bit)) for n, bit in EVER_BITS.items()},
            }
            if self.record_agents:
                rec["agents"] = agent_outcomes(b, int(w), A)
            self.episode_stats.append(rec)
        self._cap_episode_stats()

    def _cap_episode_stats(self) -> None:
        """Keep the newest `MAX_EPISODE_STATS` records; warn the first time some are dropped
        (an env stepped for days without `pop_episode_stats` would otherwise fill the memory)."""
        extra = len(self.episode_stats) - MAX_EPISODE_STATS
        if extra <= 0:
            return
        if self.dropped_episode_stats == 0:
            warnings.warn(
                f"VecEnv keeps at most {MAX_EPISODE_STATS} finished-episode records; older ones are "
                "dropped (counted in dropped_episode_stats): call pop_episode_stats() to collect them",
                UserWarning,
                stacklevel=4,
            )
        del self.episode_stats[:extra]
        self.dropped_episode_stats += extra

    def pop_episode_stats(self) -> list[dict[str, object]]:
        """Statistics of the episodes finished since the last call (per-term sums, event
        counts, agents with at least one collision / off-road / red-light event, km driven,
        `spawn_shortfall`: agent slots the spawner left empty in that episode)."""
        out, self.episode_stats = self.episode_stats, []
        return out

    def road_segments(self, slot: int) -> np.ndarray:
        """Global segment indices (`RoadMap.segments` order, maps concatenated in the env's
        order) of the road rows of agent `slot`'s current observation, row by row.

        `state.road_idx` holds atlas positions (segments sorted by grid cell, sim/atlas.py);
        this converts them, so the step itself skips the conversion.
        """
        if not 0 <= int(slot) < self.num_agents:
            raise IndexError(f"slot: expected an agent slot in [0, {self.num_agents}), got {slot!r}")
        n = int(self.buffers["road_n"][slot])
        return self.atlas["seg_id"][self.buffers["road_idx"][slot, :n]].astype(np.int64)

    @property
    def timings(self) -> dict[str, float]:
        """Seconds spent per stage since construction (stages other than reset need profile=True)."""
        return dict(self._world.timings)

    @property
    def stage_names(self) -> tuple[str, ...]:
        return (*STAGES, "reset")

    def set_term_weight(self, name: str, weight: float) -> None:
        """Set the weight of reward column `name` from the next step on, e.g. a schedule of a
        term's weight over training (`trainers.callbacks.TermWeightSchedule`). Call it between
        steps, never while another thread steps this env.

        Raises:
            ConfigError: An unknown column name (the message lists the env's) or a weight that
                is not a finite number.
        """
        if name not in self.term_names:
            names = ", ".join(self.term_names)
            raise ConfigError(f"set_term_weight: no reward column {name!r}; columns: {names}")
        number = isinstance(weight, (int, float, np.floating, np.integer)) and not isinstance(weight, bool)
        if not (number and np.isfinite(weight)):
            raise ConfigError(f"set_term_weight: {name}: expected a finite number, got {weight!r}")
        k = self.term_names.index(name)
        self._world.set_term_weight(k, float(weight))
        columns = list(self.reward.columns)  # Python columns are weighted after the step from here
        columns[k] = dataclasses.replace(columns[k], weight=float(weight))
        self.reward.columns = tuple(columns)

    def term_weight(self, name: str) -> float:
        """The current weight of reward column `name` (see `set_term_weight`)."""
        return float(self.reward.columns[self.term_names.index(name)].weight)

    # editing a running rollout (sim/edit.py): evaluations that move agents or give new routes --
    def reset_worlds(
        self, worlds: Sequence[int] | np.ndarray, scenarios: Sequence[Scenario] | None = None
    ) -> None:
        """Start new episodes in `worlds` now, as autoreset does (the episodes they end are not
        recorded in `episode_stats`).

        Args:
            worlds: Distinct world indices in [0, num_worlds).
            scenarios: One `Scenario` per world, checked as a spawner's are; None: each world
                draws its own from its generator through the spawner.

        Raises:
            ValueError: A world index out of range or repeated, a number of scenarios other
                than of worlds, or a scenario that does not fit the env (naming the field).
        """
        w = np.asarray(worlds)
        if w.ndim != 1 or (w.size and w.dtype.kind not in "iu"):
            raise ValueError(f"worlds: expected a 1-D array of world indices, got {w.dtype} {w.shape}")
        if w.size and not (w.min() >= 0 and w.max() < self.num_worlds and len(np.unique(w)) == len(w)):
            raise ValueError(f"worlds: expected distinct indices in [0, {self.num_worlds}), got {w.tolist()}")
        if scenarios is not None and len(scenarios) != len(w):
            raise ValueError(f"scenarios: expected one per world ({len(w)}), got {len(scenarios)}")
        self._reset_worlds(w.astype(np.int32), given=scenarios)
        self._run_python_obs(None)

    def set_waypoints(
        self, agents: Sequence[int] | np.ndarray, waypoints: np.ndarray, num_waypoints: np.ndarray
    ) -> None:
        """Give `agents` new routes (long-form evaluation, paper section 5): their waypoints,
        counts, and the current waypoint back to the first. The kernels read them at the next
        step; the current observation still shows the old route.

        Args:
            agents: Distinct flat agent indices i = w * A + a.
            waypoints: (len(agents), K, 2) [m] waypoints, K = `dims.K`; points past an agent's
                count are padding.
            num_waypoints: (len(agents),) valid waypoints of each, in [0, K].

        Raises:
            ValueError: Bad indices, shapes or counts, or a non-finite waypoint within the
                count (nothing is written then).
        """
        from selfplaydrive.sim import edit

        edit.set_waypoints(self, agents, waypoints, num_waypoints)

    def set_poses(
        self, agents: Sequence[int] | np.ndarray, xy: np.ndarray, heading: np.ndarray, speed: np.ndarray
    ) -> None:
        """Move `agents` (log replay, paper section 5.2): box centre, heading (and its cached
        cos / sin) and speed. The previous pose (px, py, pheading) stays: the next physics step
        starts from the new pose.

        Args:
            agents: Distinct flat agent indices i = w * A + a.
            xy: (len(agents), 2) [m] box centres.
            heading: (len(agents),) [rad] in [-pi, pi].
            speed: (len(agents),) [m/s] >= 0.

        Raises:
            ValueError: Bad indices or shapes, non-finite values, a heading outside [-pi, pi]
                or a negative speed (nothing is written then).
        """
        from selfplaydrive.sim import edit

        edit.set_poses(self, agents, xy, heading, speed)

    # saving and restoring a rollout (the format: sim/state.py) ----------------------------------
    def get_state(self) -> dict[str, Any]:
        """Copy of everything that changes while the env runs: buffers, per-world generators,
        step counters, unpopped episode statistics (a flat dict of NumPy arrays and Python
        scalars with a `version`; sim/state.py lists the fields).

        `set_state` of it, here or in an env built from the same configuration, continues the
        rollout bit for bit. `np.savez(path, **state)` stores it; `dict(np.load(path))` reads it.
        """
        from selfplaydrive.sim import state

        return state.get_state(self)

    def set_state(self, state: Mapping[str, Any]) -> None:
        """Continue from `get_state()`'s output; nothing changes when this raises.

        Raises:
            ValueError: Another version, or a field missing, unknown or of another shape or
                dtype than this env's (the message names the field).
        """
        from selfplaydrive.sim import state as state_format

        state_format.set_state(self, state)


def _reward(reward: object) -> LinearReward:
    if reward is None:
        return LinearReward()
    if isinstance(reward, Mapping):
        return LinearReward(reward)
    if not isinstance(reward, LinearReward):
        raise ConfigError(
            "reward: expected a LinearReward (selfplaydrive.rewards.LinearReward({'collision': 1.0, ...})) "
            f"or a mapping of term name -> weight, got {type(reward).__name__}"
        )
    return reward


def _read_only(a: np.ndarray) -> np.ndarray:
    v = a.view()
    v.flags.writeable = False
    return v


def check_integer(name: str, value: object, low: int, high: int | None = None) -> int:
    """`value` as an int in [low, high]; a fractional or non-numeric value is refused (int()
    would truncate 2.5 to 2 and turn "abc" into a bare ValueError).

    Raises:
        ConfigError: Naming `name` (the argument or config key), the value and the range.
    """
    if isinstance(value, (float, np.floating)) and float(value).is_integer():
        value = int(value)  # 4.0 from a YAML file is 4
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        if low <= int(value) and (high is None or int(value) <= high):
            return int(value)
    bound = f"in [{low}, {high}]" if high is not None else f">= {low}"
    raise ConfigError(f"{name}: expected an integer {bound}, got {value!r}")


def check_seed(seed: object, name: str = "seed") -> int | None:
    """A seed for numpy's generators: a non-negative integer, or None (fresh entropy).

    Raises:
        ConfigError: Naming `name` and the value.
    """
    if seed is None:
        return None
    if isinstance(seed, (int, np.integer)) and not isinstance(seed, bool) and int(seed) >= 0:
        return int(seed)
    raise ConfigError(f"{name}: expected a non-negative integer, got {seed!r}")


def _world_seeds(seed: int | None, num_worlds: int) -> np.ndarray:
    """One seed per world, drawn from the env seed."""
    return np.random.default_rng(seed).integers(0, 2**63 - 1, size=num_worlds)


def _available_memory() -> int | None:
    """Bytes of memory the process may still use: MemAvailable of /proc/meminfo, else the free
    physical pages; None where neither is known."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, OSError, ValueError):
        return None


def _check_memory(dims: Dims) -> None:
    """Refuse buffers larger than the available memory, before allocating them (NumPy's zeroed
    arrays are allocated lazily, so the process would die at the first touch instead)."""
    need = buffer_bytes(dims)
    available = _available_memory()
    if available is None or need <= available:
        return
    per_world = need / dims.W
    raise ConfigError(
        f"num_worlds={dims.W}: the simulator buffers need {need / 1e9:,.1f} GB ({per_world / 1e6:.2f} MB "
        f"per world of {dims.A} agent slots), more than the {available / 1e9:,.1f} GB of memory "
        f"available; expected num_worlds <= {int(available // per_world)}"
    )


def _box(layout: ObsLayout):
    import gymnasium as gym

    low, high = layout.bounds()
    return gym.spaces.Box(low, high, dtype=np.float32)


def _with_coeff_scale(params: SimParams, spawner: object) -> SimParams:
    """`params` with its observed-coefficient scale set (section 2.5): kept when given, else
    derived from the spawner's conditioning sampler (`ConditioningSampler.observation_scale`),
    so a sweep of the coefficient ranges rescales the observation instead of saturating it."""
    scale = getattr(getattr(spawner, "conditioning", None), "observation_scale", None)
    if params.coeff_scale is not None or not callable(scale):
        return params
    return dataclasses.replace(params, coeff_scale=tuple(scale()))
