"""Allocation of the simulator's struct-of-arrays buffers, checks and packing of a `Scenario`.

Names, shapes, dtypes and units come from the schema table (sim/schema.py), whose rows are the
fields of `sd_sim` (include/selfplaydrive_abi.h); shapes use W worlds, A agent slots, S static
slots, P pedestrian slots, K waypoints, T path points, G signal groups, N = W * A.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from selfplaydrive._sim.events import collision_scratch
from selfplaydrive._sim.observe import body_scratch
from selfplaydrive.scenario.types import Scenario
from selfplaydrive.sim.schema import (
    KINDS,
    NUM_STATS,
    SCENARIO_FIELDS,
    ScenarioField,
    buffer_fields,
    resolve,
    sizes_of,
)

NUM_TERMS = 8  # the paper's reward terms (section 2.3): the default number of term columns
__all__ = ["NUM_STATS", "NUM_TERMS", "Dims", "allocate", "buffer_bytes", "check_scenario", "pack"]


@dataclass(frozen=True)
class Dims:
    """Slot counts of an env (read from the first Scenario's array shapes): the dimension rows
    of the schema (`int` fields of `sd_sim`, sim/schema.py), in the same order."""

    W: int
    A: int
    S: int
    P: int
    K: int
    T: int
    G: int
    max_obj: int
    max_road: int
    cand_cap: int
    obs_dim: int
    num_terms: int = NUM_TERMS  # columns of `terms` / `term_sum`: the env's selected reward terms
    # physics-model components (physics/components.py): columns of act_i / act_f (the model's
    # action dimensions) and floats of model-owned state per agent slot (`phys_state`)
    act_dim: int = 2
    phys_dim: int = 0
    # floats of reward-term state per agent slot (`term_state`): the selected terms' declared
    # widths (rewards/components.py `LinearReward.bind` lays them out)
    term_state_dim: int = 0

    @staticmethod
    def of(sc: Scenario, W: int, G: int, max_obj: int, max_road: int, cand_cap: int, obs_dim: int) -> Dims:
        return Dims(
            W=W,
            A=len(sc.agent_valid),
            S=len(sc.static_valid),
            P=len(sc.ped_valid),
            K=sc.waypoints.shape[1],
            T=sc.ped_path.shape[1],
            G=G,
            max_obj=max_obj,
            max_road=max_road,
            # the collision pre-test and the observation's body table use the same per-world
            # scratch as the road gather; the kernels report the entries they write
            cand_cap=max(
                cand_cap, _kernel_scratch(len(sc.agent_valid), len(sc.static_valid), len(sc.ped_valid))
            ),
            obs_dim=obs_dim,
        )


def _kernel_scratch(A: int, S: int, P: int) -> int:
    """Scratch entries per world the collision and observation kernels need (_sim/events.pyx
    `collision_scratch`, _sim/observe.pyx `body_scratch`)."""
    return max(collision_scratch(A, S, P), body_scratch(A, S, P))


def allocate(d: Dims) -> dict[str, np.ndarray]:
    """Buffers for all worlds, one per buffer row of the schema (sim/schema.py `SIM_FIELDS`),
    C-contiguous, in table order, filled with the row's `fill` (0 but for `road_r`: no road
    gather yet, the first one searches without a hint); the kernels never clear them wholesale."""
    sizes = sizes_of(d)
    b = {}
    for f in buffer_fields():
        b[f.name] = np.zeros(resolve(f.shape, sizes), dtype=f.dtype)
        if f.fill:
            b[f.name][:] = f.fill
    return b


def buffer_bytes(d: Dims) -> int:
    """Bytes `allocate(d)` would take, computed without allocating (to refuse a num_worlds
    that cannot fit before the allocation succeeds lazily and the first touch runs out)."""
    sizes = sizes_of(d)
    return sum(
        int(np.prod(resolve(f.shape, sizes), dtype=np.int64)) * f.dtype.itemsize for f in buffer_fields()
    )


def check_scenario(sc: Scenario, d: Dims, num_maps: int) -> None:
    """Raise ValueError when `sc` does not fit the env's slots: the shape, dtype kind and values
    of every field of `SCENARIO_FIELDS` (sim/schema.py), the map index, the signal groups and
    the episode length."""
    shapes, caps = _scenario_shapes(d)
    for f in SCENARIO_FIELDS:
        _check_field(sc, f, shapes[f.name])
    for f in SCENARIO_FIELDS:
        if f.check == "count":
            _check_count(sc, f, caps[f.bound])
    _check_values(sc)
    if not 0 <= sc.map_index < num_maps:
        raise ValueError(f"scenario.map_index: expected an index in [0, {num_maps}), got {sc.map_index}")
    ng = len(sc.light_state)
    if ng > d.G:
        raise ValueError(f"scenario.light_state: expected at most {d.G} signal groups, got {ng}")
    if np.shape(sc.light_time_left) != (ng,):
        raise ValueError(
            f"scenario.light_time_left: expected shape ({ng},) (one per light_state group), got "
            f"{np.shape(sc.light_time_left)}"
        )
    if not (np.isfinite(sc.episode_length) and sc.episode_length > 0):
        raise ValueError(
            f"scenario.episode_length: expected a positive number of seconds, got {sc.episode_length}"
        )


@functools.lru_cache(maxsize=64)
def _scenario_shapes(d: Dims) -> tuple[dict[str, tuple[int, ...] | None], dict[str, int]]:
    """Each `SCENARIO_FIELDS` row's shape in elements for the env's slot counts, and the
    capacity of each "count" row's bound dim; cached per `Dims`."""
    sizes = sizes_of(d)
    shapes = {f.name: None if f.shape is None else resolve(f.shape, sizes) for f in SCENARIO_FIELDS}
    caps = {f.bound: sizes[f.bound] for f in SCENARIO_FIELDS if f.check == "count"}
    return shapes, caps


def _check_field(sc: Scenario, f: ScenarioField, shape: tuple[int, ...] | None) -> None:
    """Shape (in the env's slot counts) and dtype kind of one field."""
    a = getattr(sc, f.name)
    if shape is not None:
        got = np.shape(a)
        if got != shape:
            raise ValueError(f"scenario.{f.name}: expected shape {shape} (the env's slot counts), got {got}")
    kind = a.dtype if isinstance(a, np.ndarray) else np.asarray(a).dtype
    if kind.kind not in KINDS[f.kind]:
        raise ValueError(
            f"scenario.{f.name}: expected {f.kind} values (dtype kind in {KINDS[f.kind]!r}), got dtype {kind}"
        )


def _check_count(sc: Scenario, f: ScenarioField, cap: int) -> None:
    """The kernels index waypoints[i, :num_waypoints] and ped_path[k, :ped_num_points] without
    bounds checks: a count past the slot size would read past the row (and past the buffer in
    the last world), so it is refused here, as are non-finite points within the counts."""
    slots = np.flatnonzero(np.asarray(getattr(sc, f.valid), dtype=bool))
    n = np.asarray(getattr(sc, f.name))[slots]
    if n.size and not (n.min() >= 0 and n.max() <= cap):
        k = int(np.flatnonzero((n < 0) | (n > cap))[0])
        raise ValueError(
            f"scenario.{f.name}: expected counts in [0, {cap}] ({f.what}) for valid slots, got {int(n[k])} "
            f"in slot {int(slots[k])}"
        )
    for p in SCENARIO_FIELDS:
        if p.check == "points" and p.bound == f.name:
            _check_points(sc, p, slots, n, cap)


def _check_points(sc: Scenario, p: ScenarioField, slots: np.ndarray, n: np.ndarray, cap: int) -> None:
    pts = np.asarray(getattr(sc, p.name), dtype=np.float64)
    if np.isfinite(pts).all():
        return  # the common case: no search for the first bad point
    used = np.arange(cap)[None, :] < n[:, None]
    pts = pts[slots]
    bad = (used & ~np.isfinite(pts).all(axis=-1)).any(axis=1)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise ValueError(
            f"scenario.{p.name}: expected finite points [{p.unit}] within the first {p.bound} of each valid "
            f"slot, got {pts[k][used[k]].tolist()} in slot {int(slots[k])}"
        )


_GROUPS = {"agent_valid": "agent", "static_valid": "static", "ped_valid": "pedestrian"}


def _check_values(sc: Scenario) -> None:
    """Finite values and positive finite sizes of every valid body (the "finite" and "size" rows
    of `SCENARIO_FIELDS`): a zero length gives the bicycle model a 0/0 (section 2.6), a NaN
    position would be clipped away in the observation instead of raising. One pass over all
    values first (a reset should stay cheap); the field-by-field search only runs to name a bad
    value."""
    rows = [f for f in SCENARIO_FIELDS if f.check in ("finite", "size")]
    masks = {f.valid: np.asarray(getattr(sc, f.valid), dtype=bool) for f in rows}
    vals = [np.asarray(getattr(sc, f.name), dtype=np.float64)[masks[f.valid]].ravel() for f in rows]
    finite = np.concatenate([v for v, f in zip(vals, rows, strict=True) if f.check == "finite"])
    size = np.concatenate([v for v, f in zip(vals, rows, strict=True) if f.check == "size"])
    if np.isfinite(finite).all() and ((size > 0) & (size < np.inf)).all():
        return
    for f in rows:
        x = np.asarray(getattr(sc, f.name), dtype=np.float64)[masks[f.valid]]
        bad = ~np.isfinite(x) if f.check == "finite" else ~(np.isfinite(x) & (x > 0))
        if bad.any():
            k = int(np.flatnonzero(bad.reshape(len(x), -1).any(axis=1))[0])
            want = "finite values" if f.check == "finite" else f"positive finite sizes [{f.unit}]"
            raise ValueError(
                f"scenario.{f.name}: expected {want} for valid {_GROUPS[f.valid]} slots, got {x[k].tolist()} "
                f"in slot {int(np.flatnonzero(masks[f.valid])[k])}"
            )


def pack(b: dict[str, np.ndarray], d: Dims, w: int, sc: Scenario, dt: float, rng_key: int) -> None:
    """Write scenario `sc` into world `w` of buffers `b` (episode start, statistics zeroed)."""
    a = slice(w * d.A, (w + 1) * d.A)
    heading = np.arctan2(
        np.sin(sc.agent_heading.astype(np.float64)), np.cos(sc.agent_heading.astype(np.float64))
    )
    b["x"][a] = b["px"][a] = sc.agent_xy[:, 0]
    b["y"][a] = b["py"][a] = sc.agent_xy[:, 1]
    b["heading"][a] = b["pheading"][a] = heading
    b["hcos"][a] = np.cos(heading)
    b["hsin"][a] = np.sin(heading)
    b["speed"][a] = np.where(sc.agent_valid, sc.agent_speed, 0.0)
    b["length"][a] = sc.agent_length
    b["width"][a] = sc.agent_width
    b["coeffs"][a] = sc.coeffs
    b["hidden"][a] = sc.hidden
    b["waypoints"][a] = sc.waypoints
    b["num_wp"][a] = sc.num_waypoints
    b["active"][a] = sc.agent_valid
    b["agent_valid"][a] = sc.agent_valid
    # term, trunc, reward and terms keep the last step's values: an autoreset world still
    # reports how its agents' episodes ended
    for name in ("a_long", "a_lat", "wp_idx", "obstacle", "events", "ever"):
        b[name][a] = 0
    _pack_static(b, d, w, sc)
    _pack_peds(b, d, w, sc)
    g = slice(w * d.G, (w + 1) * d.G)
    ng = len(sc.light_state)
    on = bool(sc.lights_enabled)
    b["light_state"][g] = 0
    b["light_time"][g] = 1e9  # groups the map does not have never change
    if on and ng:
        b["light_state"][w * d.G : w * d.G + ng] = sc.light_state
        b["light_time"][w * d.G : w * d.G + ng] = sc.light_time_left
    b["lights_on"][w] = on
    b["map_id"][w] = sc.map_index
    b["step"][w] = 0
    b["max_steps"][w] = max(1, round(sc.episode_length / dt))
    b["done"][w] = 0
    b["rng_key"][w] = rng_key
    b["rng_ctr"][w] = 0
    b["term_sum"][w] = 0.0
    b["ev_count"][w] = 0
    b["dist"][w] = 0.0


def _pack_static(b: dict[str, np.ndarray], d: Dims, w: int, sc: Scenario) -> None:
    s = slice(w * d.S, (w + 1) * d.S)
    b["st_x"][s] = sc.static_xy[:, 0]
    b["st_y"][s] = sc.static_xy[:, 1]
    b["st_cos"][s] = np.cos(sc.static_heading.astype(np.float64))
    b["st_sin"][s] = np.sin(sc.static_heading.astype(np.float64))
    b["st_len"][s] = sc.static_length
    b["st_wid"][s] = sc.static_width
    b["st_valid"][s] = sc.static_valid


def _pack_peds(b: dict[str, np.ndarray], d: Dims, w: int, sc: Scenario) -> None:
    p = slice(w * d.P, (w + 1) * d.P)
    b["ped_path"][p] = sc.ped_path
    b["ped_np"][p] = sc.ped_num_points
    b["ped_speed"][p] = sc.ped_speed
    b["ped_start"][p] = sc.ped_start_time
    b["ped_len"][p] = sc.ped_size[:, 0]
    b["ped_wid"][p] = sc.ped_size[:, 1]
    b["ped_valid"][p] = sc.ped_valid & (sc.ped_num_points >= 2)
    b["ped_here"][p] = b["ped_valid"][p]
    b["ped_x"][p] = sc.ped_path[:, 0, 0]
    b["ped_y"][p] = sc.ped_path[:, 0, 1]
    b["ped_cos"][p] = 1.0
    b["ped_sin"][p] = 0.0
    b["ped_vx"][p] = 0.0
    b["ped_vy"][p] = 0.0
