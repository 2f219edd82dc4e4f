"""Allocation of the simulator's struct-of-arrays buffers and packing of a `Scenario`.

Array names are the `Sim` field names of _sim/common.pxd; shapes use W worlds, A agent slots,
S static slots, P pedestrian slots, K waypoints, T path points, G signal groups, N = W * A.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from selfplaydrive._sim.events import collision_scratch
from selfplaydrive._sim.observe import body_scratch
from selfplaydrive.scenario.types import COEFF_NAMES, HIDDEN_PARAMS, Scenario

NUM_TERMS = 8  # the paper's reward terms (section 2.3): the default number of term columns
NUM_STATS = 8


@dataclass(frozen=True)
class Dims:
    """Slot counts of an env (read from the first Scenario's array shapes)."""

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
    """Zeroed buffers for all worlds (the kernels never clear them wholesale)."""
    b = {name: np.zeros(shape, dtype=dtype) for name, (shape, dtype) in _shapes(d).items()}
    b["road_r"][:] = -1.0  # no road gather yet: the first one searches without a hint
    return b


def buffer_bytes(d: Dims) -> int:
    """Bytes `allocate(d)` would take, computed without allocating (to refuse a num_worlds
    that cannot fit before the allocation succeeds lazily and the first touch runs out)."""
    return sum(
        int(np.prod(shape, dtype=np.int64)) * np.dtype(dt).itemsize for shape, dt in _shapes(d).values()
    )


def _shapes(d: Dims) -> dict[str, tuple[tuple[int, ...], type]]:
    """Shape and dtype of every buffer."""
    N, f4, u1, i4 = d.W * d.A, np.float32, np.uint8, np.int32
    shapes: dict[str, tuple[tuple[int, ...], type]] = {}
    for name in (
        "x y heading hcos hsin speed px py pheading length width a_long a_lat lane_s lane_alpha reward "
        "road_r road_x road_y"
    ).split():
        shapes[name] = ((N,), f4)
    for name in "num_wp wp_idx road_n obj_rows road_rows".split():
        shapes[name] = ((N,), i4)
    for name in "agent_valid active obstacle lane_valid events ever term trunc".split():
        shapes[name] = ((N,), u1)
    shapes.update(
        coeffs=((N, len(COEFF_NAMES)), f4),
        hidden=((N, len(HIDDEN_PARAMS)), f4),
        waypoints=((N, d.K, 2), f4),
        road_idx=((N, d.max_road), i4),
        act_i=((N, d.act_dim), i4),
        act_f=((N, d.act_dim), f4),
        phys_state=((N, d.phys_dim), f4),
        term_state=((N, d.term_state_dim), f4),
        terms=((N, d.num_terms), f4),
        obs=((N, d.obs_dim), f4),
        final_obs=((N, d.obs_dim), f4),
        st_valid=((d.W * d.S,), u1),
        ped_path=((d.W * d.P, d.T, 2), f4),
        ped_np=((d.W * d.P,), i4),
        ped_valid=((d.W * d.P,), u1),
        ped_here=((d.W * d.P,), u1),
        light_state=((d.W * d.G,), np.int8),
        light_time=((d.W * d.G,), f4),
        map_id=((d.W,), i4),
        step=((d.W,), i4),
        max_steps=((d.W,), i4),
        lights_on=((d.W,), u1),
        done=((d.W,), u1),
        rng_key=((d.W,), np.uint64),
        rng_ctr=((d.W,), np.uint64),
        term_sum=((d.W, d.num_terms), np.float64),
        ev_count=((d.W, NUM_STATS), np.int64),
        dist=((d.W,), np.float64),
        cand=((d.W, d.cand_cap), i4),
        cand_d=((d.W, d.cand_cap), f4),
    )
    for name in "st_x st_y st_cos st_sin st_len st_wid".split():
        shapes[name] = ((d.W * d.S,), f4)
    for name in (
        "ped_speed ped_start ped_len ped_wid ped_x ped_y ped_px ped_py ped_cos ped_sin ped_vx ped_vy".split()
    ):
        shapes[name] = ((d.W * d.P,), f4)
    return shapes


def check_scenario(sc: Scenario, d: Dims, num_maps: int) -> None:
    """Raise ValueError when `sc` does not fit the env's slots."""
    expect = {
        "agent_valid": (d.A,),
        "agent_xy": (d.A, 2),
        "waypoints": (d.A, d.K, 2),
        "coeffs": (d.A, len(COEFF_NAMES)),
        "hidden": (d.A, len(HIDDEN_PARAMS)),
        "static_valid": (d.S,),
        "static_xy": (d.S, 2),
        "ped_valid": (d.P,),
        "ped_path": (d.P, d.T, 2),
    }
    for name, shape in expect.items():
        got = np.shape(getattr(sc, name))
        if got != shape:
            raise ValueError(f"scenario.{name}: expected shape {shape} (the env's slot counts), got {got}")
    _check_counts(sc, d)
    _check_bodies(sc)
    if not 0 <= sc.map_index < num_maps:
        raise ValueError(f"scenario.map_index: expected an index in [0, {num_maps}), got {sc.map_index}")
    if len(sc.light_state) > d.G:
        raise ValueError(
            f"scenario.light_state: expected at most {d.G} signal groups, got {len(sc.light_state)}"
        )
    if not (np.isfinite(sc.episode_length) and sc.episode_length > 0):
        raise ValueError(
            f"scenario.episode_length: expected a positive number of seconds, got {sc.episode_length}"
        )


def _check_counts(sc: Scenario, d: Dims) -> None:
    """The kernels index waypoints[i, :num_waypoints] and ped_path[k, :ped_num_points] without
    bounds checks: a count past the slot size would read past the row (and past the buffer in
    the last world), so it is refused here, as are non-finite points within the counts."""
    for name, points, valid, cap, what in (
        ("num_waypoints", "waypoints", sc.agent_valid, d.K, "max_waypoints"),
        ("ped_num_points", "ped_path", sc.ped_valid, d.T, "path points"),
    ):
        slots = np.flatnonzero(np.asarray(valid, dtype=bool))
        n = np.asarray(getattr(sc, name))[slots]
        if n.size and not (n.min() >= 0 and n.max() <= cap):
            k = int(np.flatnonzero((n < 0) | (n > cap))[0])
            raise ValueError(
                f"scenario.{name}: expected counts in [0, {cap}] ({what}) for valid slots, got {int(n[k])} "
                f"in slot {int(slots[k])}"
            )
        pts = np.asarray(getattr(sc, points), dtype=np.float64)
        if np.isfinite(pts).all():
            continue  # the common case: no search for the first bad point
        used = np.arange(cap)[None, :] < n[:, None]
        pts = pts[slots]
        bad = (used & ~np.isfinite(pts).all(axis=-1)).any(axis=1)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise ValueError(
                f"scenario.{points}: expected finite points [m] within the first {name} of each valid "
                f"slot, got {pts[k][used[k]].tolist()} in slot {int(slots[k])}"
            )


_BODY_FIELDS = (
    (
        "agent",
        "agent_valid",
        ("agent_xy", "agent_heading", "agent_speed", "coeffs", "hidden"),
        ("agent_length", "agent_width"),
    ),
    ("static", "static_valid", ("static_xy", "static_heading"), ("static_length", "static_width")),
    ("pedestrian", "ped_valid", ("ped_speed", "ped_start_time"), ("ped_size",)),
)


def _check_bodies(sc: Scenario) -> None:
    """Finite positions and headings and positive finite sizes for every valid body: a zero
    length gives the bicycle model a 0/0 (section 2.6), a NaN position would be clipped away
    in the observation instead of raising. One pass over all values first (a reset should
    stay cheap); the field-by-field search only runs to name a bad value."""
    vals, sizes = [], []
    for _, valid, fields, size_fields in _BODY_FIELDS:
        v = np.asarray(getattr(sc, valid), dtype=bool)
        vals += [np.asarray(getattr(sc, n), dtype=np.float64)[v].ravel() for n in fields]
        sizes += [np.asarray(getattr(sc, n), dtype=np.float64)[v].ravel() for n in size_fields]
    flat, size = np.concatenate(vals), np.concatenate(sizes)
    if np.isfinite(flat).all() and ((size > 0) & (size < np.inf)).all():
        return
    for group, valid, fields, size_fields in _BODY_FIELDS:
        v = np.asarray(getattr(sc, valid), dtype=bool)
        for name in fields + size_fields:
            x = np.asarray(getattr(sc, name), dtype=np.float64)[v]
            bad = ~np.isfinite(x) if name in fields else ~(np.isfinite(x) & (x > 0))
            if bad.any():
                k = int(np.flatnonzero(bad.reshape(len(x), -1).any(axis=1))[0])
                want = "finite values" if name in fields else "positive finite sizes [m]"
                raise ValueError(
                    f"scenario.{name}: expected {want} for valid {group} slots, got {x[k].tolist()} "
                    f"in slot {int(np.flatnonzero(v)[k])}"
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
