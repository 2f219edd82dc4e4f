"""The world-state schema: one table of every field of the simulator state (paper section 2).

`SIM_FIELDS` lists the fields of the typed view the kernels and components read, `sd_sim` of
include/selfplaydrive_abi.h, in declaration order: the dimensions (C `int`, the `Dims` of the
env) and the buffers (pointers into NumPy arrays), plus the buffers the Python side alone keeps
(`in_struct` False, after the struct's fields). From it:

- `sim.buffers.allocate` allocates the buffers (shape from the row's dims, dtype from its C type);
- `struct_layout` gives the byte offset of every struct field, which `_sim/world.pyx` `World`
  fills from the buffers (no per-field binding code);
- tests/sim/test_schema.py compares the table with the declarations in selfplaydrive_abi.h,
  selfplaydrive_abi.pxd, _sim/common.pxd and the numba mirror rewards/numba_abi.py, naming any
  field that differs.

`SCENARIO_FIELDS` lists what a spawner hands over (`Scenario`, section 2.2), from which
`sim.buffers.check_scenario` derives its shape, dtype and value checks.

Adding a field to the state is one row here plus its declaration in the header and the `.pxd`
(the schema test prints the lines it expects); a new dimension also needs its `Dims` field.
Fields are only ever appended (selfplaydrive_abi.h "Compatibility").
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from selfplaydrive.scenario.types import COEFF_NAMES, HIDDEN_PARAMS

NUM_STATS = 8  # columns of `ev_count` (SD_NUM_STATS)
OWNERS = ("sim", "spawner", "physics", "reward", "encoder")
# C type of a struct field -> NumPy dtype of the buffer it points at (or of the dimension)
C_DTYPES = {
    "int": np.int32,
    "float": np.float32,
    "double": np.float64,
    "int8_t": np.int8,
    "uint8_t": np.uint8,
    "int32_t": np.int32,
    "int64_t": np.int64,
    "uint64_t": np.uint64,
}
# sizes a shape may name besides the `Dims` fields
CONSTANTS = {"num_coeffs": len(COEFF_NAMES), "num_hidden": len(HIDDEN_PARAMS), "num_stats": NUM_STATS}


@dataclass(frozen=True)
class Field:
    """One field of the world state.

    Attributes:
        name: Field name (`sd_sim` member, buffer name of `VecEnv.buffers`).
        ctype: C type of the struct member: "int" for a dimension, "float*", "uint8_t*", ...
            for a buffer (the element type gives the buffer's dtype).
        shape: Dimensions of the buffer: `Dims` field names, "N" (= W * A), products such as
            "W*S", the `CONSTANTS` names or integers; () for a dimension.
        unit: Physical unit ("m", "m/s", "rad", ...; "" when none).
        owner: Who writes it: the spawner (packed at reset), the physics model, the reward
            terms, the observation encoder, or the simulator's own stages ("sim").
        doc: One line on the content.
        fill: Value of a freshly allocated buffer.
        in_struct: False for a buffer the Python side alone keeps (not in `sd_sim`).
    """

    name: str
    ctype: str
    shape: tuple[str | int, ...]
    unit: str
    owner: str
    doc: str
    fill: float = 0.0
    in_struct: bool = True

    @property
    def is_dim(self) -> bool:
        """A dimension (a C `int` of the struct, no buffer)."""
        return self.ctype == "int"

    @property
    def dtype(self) -> np.dtype:
        """dtype of the buffer (of the value, for a dimension)."""
        return np.dtype(C_DTYPES[self.ctype.rstrip("*")])


def _dims(*rows: tuple[str, str]) -> list[Field]:
    return [Field(n, "int", (), "", "sim", doc) for n, doc in rows]


def _per(ctype: str, shape: tuple[str | int, ...], owner: str, rows: str) -> list[Field]:
    """Rows of one C type and shape: `rows` holds "name | unit | doc" lines."""
    out = []
    for line in rows.strip().splitlines():
        name, unit, doc = (s.strip() for s in line.split("|"))
        out.append(Field(name, ctype, shape, unit, owner, doc))
    return out


N, NS, NP, NG, W = ("N",), ("W*S",), ("W*P",), ("W*G",), ("W",)

SIM_FIELDS: tuple[Field, ...] = (
    *_dims(
        ("W", "worlds"),
        ("A", "agent slots per world"),
        ("S", "static vehicle slots per world"),
        ("P", "pedestrian slots per world"),
        ("K", "waypoint slots per agent"),
        ("T", "points per pedestrian path"),
        ("G", "signal groups per world (max over maps, >= 1)"),
        ("max_obj", "observed objects per agent"),
        ("max_road", "observed road segments per agent"),
        ("cand_cap", "scratch capacity per world for road candidates"),
        ("obs_dim", "floats per observation row"),
        ("num_terms", "M, columns of terms and term_sum (the selected reward terms)"),
    ),
    # agents (W * A)
    *_per(
        "float*",
        N,
        "physics",
        """
        x | m | box centre x
        y | m | box centre y
        heading | rad | in (-pi, pi]
        hcos | | cos(heading), cached by physics
        hsin | | sin(heading)
        speed | m/s | >= 0, along the direction of travel
        px | m | centre x before the last physics step
        py | m | centre y before the last physics step
        pheading | rad | heading before the last physics step
        """,
    ),
    *_per("float*", N, "spawner", "length | m | box length\nwidth | m | box width"),
    *_per(
        "float*",
        N,
        "physics",
        """
        a_long | m/s^2 | longitudinal acceleration applied in the last step
        a_lat | m/s^2 | lateral acceleration applied in the last step
        """,
    ),
    Field("coeffs", "float*", ("N", "num_coeffs"), "", "spawner", "reward coefficients (observed)"),
    Field("hidden", "float*", ("N", "num_hidden"), "", "spawner", "friction mu, accel gain, steer gain"),
    Field("waypoints", "float*", ("N", "K", 2), "m", "spawner", "route waypoints"),
    Field("num_wp", "int32_t*", N, "", "spawner", "valid waypoints"),
    Field("wp_idx", "int32_t*", N, "", "sim", "index of the current waypoint (num_wp: all reached)"),
    Field("active", "uint8_t*", N, "", "sim", "slot holds an agent that is still playing"),
    Field("obstacle", "uint8_t*", N, "", "sim", "ended agent left on the road as a static obstacle"),
    Field("lane_s", "float*", N, "m", "sim", "signed lateral offset from the associated centerline"),
    Field("lane_alpha", "float*", N, "rad", "sim", "heading minus lane direction, in (-pi, pi]"),
    Field("lane_valid", "uint8_t*", N, "", "sim", "1 when a centerline was found within lane_radius"),
    Field("events", "uint8_t*", N, "", "sim", "SD_EV_* bits of the last step"),
    Field("ever", "uint8_t*", N, "", "sim", "SD_EV_* bits accumulated over the episode"),
    Field("road_idx", "int32_t*", ("N", "max_road"), "", "sim", "atlas positions of the observed segments"),
    Field("road_n", "int32_t*", N, "", "sim", "valid entries in road_idx"),
    Field("obj_rows", "int32_t*", N, "", "encoder", "object rows written at the last observation"),
    Field("road_rows", "int32_t*", N, "", "encoder", "road rows written at the last observation"),
    Field("road_r", "float*", N, "m", "sim", "radius of the last road gather (< 0: none yet)", fill=-1.0),
    Field("road_x", "float*", N, "m", "sim", "position x of the last road gather"),
    Field("road_y", "float*", N, "m", "sim", "position y of the last road gather"),
    Field("act_i", "int32_t*", ("N", "act_dim"), "", "sim", "discrete action indices"),
    Field("act_f", "float*", ("N", "act_dim"), "", "sim", "continuous actions [m/s^2], [rad]"),
    Field("reward", "float*", N, "", "reward", "summed reward of the last step"),
    Field("terms", "float*", ("N", "num_terms"), "", "reward", "per-term reward of the last step"),
    Field("term", "uint8_t*", N, "", "sim", "terminated in the last step"),
    Field("trunc", "uint8_t*", N, "", "sim", "truncated (time limit) in the last step"),
    Field("obs", "float*", ("N", "obs_dim"), "", "encoder", "observations"),
    Field("final_obs", "float*", ("N", "obs_dim"), "", "encoder", "observation at the end of an episode"),
    # static vehicles (W * S)
    *_per(
        "float*",
        NS,
        "spawner",
        """
        st_x | m | centre x
        st_y | m | centre y
        st_cos | | cos(heading)
        st_sin | | sin(heading)
        st_len | m | box length
        st_wid | m | box width
        """,
    ),
    Field("st_valid", "uint8_t*", NS, "", "spawner", "slot holds a static vehicle"),
    # pedestrians (W * P)
    Field("ped_path", "float*", ("W*P", "T", 2), "m", "spawner", "path polyline"),
    Field("ped_np", "int32_t*", NP, "", "spawner", "valid path points"),
    *_per(
        "float*",
        NP,
        "spawner",
        """
        ped_speed | m/s | walking speed
        ped_start | s | start time
        ped_len | m | box length
        ped_wid | m | box width
        """,
    ),
    Field("ped_valid", "uint8_t*", NP, "", "spawner", "slot holds a pedestrian"),
    Field("ped_here", "uint8_t*", NP, "", "sim", "pedestrian is present (0 after vanishing)"),
    *_per(
        "float*",
        NP,
        "sim",
        """
        ped_x | m | current centre x
        ped_y | m | current centre y
        ped_px | m | centre x before the last step
        ped_py | m | centre y before the last step
        ped_cos | | cos(heading)
        ped_sin | | sin(heading)
        ped_vx | m/s | velocity x, world frame
        ped_vy | m/s | velocity y, world frame
        """,
    ),
    # traffic lights (W * G)
    Field("light_state", "int8_t*", NG, "", "sim", "SD_LIGHT_* per signal group"),
    Field("light_time", "float*", NG, "s", "sim", "time until the group's next change"),
    # worlds (W)
    Field("map_id", "int32_t*", W, "", "spawner", "map of the world in the atlas"),
    Field("step", "int32_t*", W, "", "sim", "steps taken in the current episode"),
    Field("max_steps", "int32_t*", W, "", "spawner", "episode length in steps"),
    Field("lights_on", "uint8_t*", W, "", "spawner", "0 in the episodes where every light stays off"),
    Field("done", "uint8_t*", W, "", "sim", "world ended in the last step (autoreset follows)"),
    Field("rng_key", "uint64_t*", W, "", "sim", "counter-based RNG key of the world"),
    Field("rng_ctr", "uint64_t*", W, "", "sim", "counter-based RNG counter of the world"),
    Field("term_sum", "double*", ("W", "num_terms"), "", "reward", "per-term reward sums of the episode"),
    Field("ev_count", "int64_t*", ("W", "num_stats"), "", "sim", "event counts of the episode"),
    Field("dist", "double*", W, "m", "sim", "distance driven by all agents of the episode"),
    Field("cand", "int32_t*", ("W", "cand_cap"), "", "sim", "scratch: candidate indices"),
    Field("cand_d", "float*", ("W", "cand_cap"), "m^2", "sim", "scratch: candidate squared distances"),
    # physics-model components (appended, ABI 1)
    *_dims(
        ("act_dim", "D, columns of act_i and act_f: the model's action dimensions"),
        ("phys_dim", "floats of model-owned state per agent slot (0: none)"),
    ),
    Field("phys_state", "float*", ("N", "phys_dim"), "", "physics", "state the physics model owns"),
    # reward terms with per-agent state (appended, ABI 1; rewards/components.py LinearReward.bind)
    *_dims(("term_state_dim", "floats of reward-term state per agent slot (0: none)")),
    Field("term_state", "float*", ("N", "term_state_dim"), "", "reward", "state the reward terms own"),
    # the Python side alone (not in sd_sim)
    Field(
        "agent_valid",
        "uint8_t*",
        N,
        "",
        "spawner",
        "slot held an agent at the episode start",
        in_struct=False,
    ),
)


@dataclass(frozen=True)
class ScenarioField:
    """One field of a `Scenario` as `check_scenario` checks it.

    Attributes:
        name: `Scenario` attribute.
        kind: Accepted dtype kind: "bool" (bool or integer), "int" (bool or integer), "float"
            (bool, integer or float); anything else (float counts, objects) is refused.
        shape: Slot dimensions ("A", "S", "P", "K", "T", `CONSTANTS` names, integers); None
            for a field whose shape is checked apart (light_state: at most G groups).
        unit: Physical unit ("" when none).
        valid: The mask of the slots whose values are checked ("" for none).
        check: "finite" (every value of a valid slot), "size" (positive and finite), "count"
            (in [0, `bound`], the slots' capacity), "points" (finite within the count field
            `bound`), "" (shape and dtype only).
        bound: For "count" the capacity dim, for "points" the count field.
        what: How an error message names the capacity or the value.
    """

    name: str
    kind: str
    shape: tuple[str | int, ...] | None
    unit: str = ""
    valid: str = ""
    check: str = ""
    bound: str = ""
    what: str = ""


SCENARIO_FIELDS: tuple[ScenarioField, ...] = (
    ScenarioField("agent_valid", "bool", ("A",)),
    ScenarioField("agent_xy", "float", ("A", 2), "m", "agent_valid", "finite"),
    ScenarioField("agent_heading", "float", ("A",), "rad", "agent_valid", "finite"),
    ScenarioField("agent_speed", "float", ("A",), "m/s", "agent_valid", "finite"),
    ScenarioField("agent_length", "float", ("A",), "m", "agent_valid", "size"),
    ScenarioField("agent_width", "float", ("A",), "m", "agent_valid", "size"),
    ScenarioField("num_waypoints", "int", ("A",), "", "agent_valid", "count", "K", "max_waypoints"),
    ScenarioField("waypoints", "float", ("A", "K", 2), "m", "agent_valid", "points", "num_waypoints"),
    ScenarioField("coeffs", "float", ("A", "num_coeffs"), "", "agent_valid", "finite"),
    ScenarioField("hidden", "float", ("A", "num_hidden"), "", "agent_valid", "finite"),
    ScenarioField("static_valid", "bool", ("S",)),
    ScenarioField("static_xy", "float", ("S", 2), "m", "static_valid", "finite"),
    ScenarioField("static_heading", "float", ("S",), "rad", "static_valid", "finite"),
    ScenarioField("static_length", "float", ("S",), "m", "static_valid", "size"),
    ScenarioField("static_width", "float", ("S",), "m", "static_valid", "size"),
    ScenarioField("ped_valid", "bool", ("P",)),
    ScenarioField("ped_num_points", "int", ("P",), "", "ped_valid", "count", "T", "path points"),
    ScenarioField("ped_path", "float", ("P", "T", 2), "m", "ped_valid", "points", "ped_num_points"),
    ScenarioField("ped_speed", "float", ("P",), "m/s", "ped_valid", "finite"),
    ScenarioField("ped_start_time", "float", ("P",), "s", "ped_valid", "finite"),
    ScenarioField("ped_size", "float", ("P", 2), "m", "ped_valid", "size"),
    ScenarioField("light_state", "int", None),
    ScenarioField("light_time_left", "float", None, "s"),
)
# accepted dtype kinds (numpy `dtype.kind`) per ScenarioField.kind
KINDS = {"bool": "biu", "int": "biu", "float": "biuf"}


def resolve(shape: tuple[str | int, ...], sizes: dict[str, int]) -> tuple[int, ...]:
    """Shape in elements: each entry an int, a name of `sizes` or a product "W*S"."""
    out = []
    for s in shape:
        if isinstance(s, int):
            out.append(s)
            continue
        n = 1
        for part in s.split("*"):
            n *= sizes[part]
        out.append(n)
    return tuple(out)


def sizes_of(dims: object) -> dict[str, int]:
    """The sizes a shape may name: every dimension row of `SIM_FIELDS` read from `dims` (a
    `Dims`), N = W * A, and the `CONSTANTS`."""
    out = {f.name: int(getattr(dims, f.name)) for f in SIM_FIELDS if f.is_dim}
    out["N"] = out["W"] * out["A"]
    out.update(CONSTANTS)
    return out


def buffer_fields() -> tuple[Field, ...]:
    """The rows that are buffers (struct pointers and Python-only buffers), in table order."""
    return tuple(f for f in SIM_FIELDS if not f.is_dim)


def struct_fields() -> tuple[Field, ...]:
    """The rows of `sd_sim`, in declaration order."""
    return tuple(f for f in SIM_FIELDS if f.in_struct)


def struct_dtype() -> np.dtype:
    """NumPy dtype with the C layout of `sd_sim` (dimensions int32, pointers uintp addresses)."""
    return np.dtype(
        [(f.name, np.int32 if f.is_dim else np.uintp) for f in struct_fields()],
        align=True,
    )


def struct_layout() -> tuple[list[tuple[str, int, np.dtype | None]], int]:
    """What `World` fills `sd_sim` from: (name, byte offset, buffer dtype, or None for a
    dimension) per field, and the struct's size in bytes (checked against `sizeof(sd_sim)`)."""
    dt = struct_dtype()
    fields: Mapping[str, tuple[Any, ...]] = dt.fields or {}
    rows = [(f.name, int(fields[f.name][1]), None if f.is_dim else f.dtype) for f in struct_fields()]
    return rows, int(dt.itemsize)
