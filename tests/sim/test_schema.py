"""The world-state schema (sim/schema.py) against every declaration of the typed view: the C
header, the Cython `.pxd` of the ABI, the kernels' _sim/common.pxd and the numba mirror. A
mismatch names the field and prints the declaration the schema expects."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest

import selfplaydrive
from selfplaydrive.sim import schema
from selfplaydrive.sim.buffers import Dims, allocate, buffer_bytes

INCLUDE = Path(selfplaydrive.get_include())
SIM_DIR = Path(selfplaydrive.__file__).parent / "_sim"


def header_fields(text: str) -> list[tuple[str, str]]:
    """(name, C type) of `typedef struct sd_sim { ... } sd_sim;`, comments removed."""
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
    body = re.search(r"typedef struct sd_sim \{(.*?)\} sd_sim;", text, flags=re.S)
    assert body is not None, "selfplaydrive_abi.h declares no struct sd_sim"
    out = []
    for decl in body.group(1).split(";"):
        decl = " ".join(decl.split())
        if decl:
            ctype, name = decl.replace(" *", "* ").rsplit(" ", 1)
            out.append((name, ctype.replace(" ", "")))
    return out


def pxd_fields(text: str) -> list[tuple[str, str]]:
    """(name, C type) of `ctypedef struct Sim "sd_sim":` (the indented block after it)."""
    lines = text.splitlines()
    start = next(k for k, line in enumerate(lines) if line.strip() == 'ctypedef struct Sim "sd_sim":')
    out = []
    for line in lines[start + 1 :]:
        if not line.startswith(" " * 8) or not line.strip():
            break
        ctype, name = line.split("#")[0].strip().rsplit(" ", 1)
        out.append((name, ctype.replace(" ", "")))
    return out


def expected() -> list[tuple[str, str]]:
    return [(f.name, f.ctype) for f in schema.struct_fields()]


def compare(got: list[tuple[str, str]], where: str, render) -> None:
    """Assert `got` equals the schema's struct fields, naming the first field that differs."""
    want = expected()
    for k, (w, g) in enumerate(zip(want, got, strict=False)):
        assert g == w, (
            f"{where}: field {k} is {g[1]} {g[0]}, the schema (sim/schema.py) has {w[1]} {w[0]}; "
            f"expected the declaration {render(*w)!r}"
        )
    missing = [render(*w) for w in want[len(got) :]]
    assert not missing, f"{where}: fields of the schema not declared, expected {missing}"
    extra = [name for name, _ in got[len(want) :]]
    assert not extra, f"{where}: fields not in the schema (sim/schema.py): {extra}"


def test_header_declares_the_schema_fields_in_order():
    text = (INCLUDE / "selfplaydrive_abi.h").read_text()
    compare(header_fields(text), "selfplaydrive_abi.h sd_sim", lambda n, c: f"{c} {n};")


def test_pxd_declares_the_schema_fields_in_order():
    text = (INCLUDE / "selfplaydrive_abi.pxd").read_text()
    compare(pxd_fields(text), "selfplaydrive_abi.pxd Sim", lambda n, c: f"{c} {n}")


def test_kernels_cimport_the_shipped_declarations():
    """_sim/common.pxd declares nothing of its own: the kernels see the ABI's `Sim`."""
    text = (SIM_DIR / "common.pxd").read_text()
    code = [line for line in re.sub(r'""".*?"""', "", text, flags=re.S).splitlines() if line.strip()]
    code = [line for line in code if not line.startswith("#")]
    assert code == ["from selfplaydrive_abi cimport *"], f"common.pxd: expected the cimport alone, got {code}"


def test_numba_mirror_reads_the_same_fields_and_offsets():
    numba_abi = pytest.importorskip("selfplaydrive.rewards.numba_abi")
    got = [(n, c.replace(" ", "")) for n, c in numba_abi.struct_fields("sim")]
    compare(got, "rewards/numba_abi.py SIM", lambda n, c: f"{c} {n}")
    dt = schema.struct_dtype()
    for name in dt.names:
        assert getattr(numba_abi.SIM, name) == dt.fields[name][1], f"numba_abi SIM.{name}: offset differs"


def test_a_mismatch_names_the_field():
    good = expected()
    bad = [(n, "double*" if n == "speed" else c) for n, c in good]
    with pytest.raises(AssertionError, match=r"float\* speed"):
        compare(bad, "test", lambda n, c: f"{c} {n};")
    with pytest.raises(AssertionError, match="term_state"):
        compare(good[:-1], "test", lambda n, c: f"{c} {n};")
    with pytest.raises(AssertionError, match="extra_field"):
        compare([*good, ("extra_field", "int")], "test", lambda n, c: f"{c} {n};")


def test_header_parser_on_a_hand_written_struct():
    text = "typedef struct sd_sim {\n    int W;   /* worlds */\n    const float *x; /* [m] */\n} sd_sim;"
    assert header_fields(text) == [("W", "int"), ("x", "constfloat*")]


def test_dims_are_the_dimension_rows():
    dims = [f.name for f in schema.SIM_FIELDS if f.is_dim]
    assert [f.name for f in dataclasses.fields(Dims)] == dims


def test_rows_are_well_formed():
    names = [f.name for f in schema.SIM_FIELDS]
    assert len(names) == len(set(names))
    sizes = schema.sizes_of(Dims(1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1))
    for f in schema.SIM_FIELDS:
        assert f.owner in schema.OWNERS, f.name
        assert f.ctype.rstrip("*") in schema.C_DTYPES, f.name
        assert f.is_dim == (f.shape == ()), f.name
        schema.resolve(f.shape, sizes)  # every dim of a shape is known
    assert not any(f.is_dim for f in schema.SIM_FIELDS if not f.in_struct)


def test_allocate_follows_the_table():
    """Hand-computed shapes of a few rows for W=2, A=3, S=4, P=5, K=6, T=7, G=2."""
    d = Dims(W=2, A=3, S=4, P=5, K=6, T=7, G=2, max_obj=8, max_road=9, cand_cap=10, obs_dim=11, phys_dim=3)
    b = allocate(d)
    assert list(b) == [f.name for f in schema.buffer_fields()]
    assert b["x"].shape == (6,) and b["x"].dtype == np.float32
    assert b["waypoints"].shape == (6, 6, 2)
    assert b["coeffs"].shape == (6, 8) and b["hidden"].shape == (6, 3)
    assert b["st_valid"].shape == (8,) and b["st_valid"].dtype == np.uint8
    assert b["ped_path"].shape == (10, 7, 2)
    assert b["light_state"].shape == (4,) and b["light_state"].dtype == np.int8
    assert b["term_sum"].shape == (2, 8) and b["term_sum"].dtype == np.float64
    assert b["ev_count"].shape == (2, 8) and b["ev_count"].dtype == np.int64
    assert b["phys_state"].shape == (6, 3) and b["agent_valid"].shape == (6,)
    assert (b["road_r"] == -1.0).all() and not b["x"].any()
    assert all(a.flags.c_contiguous for a in b.values())
    assert buffer_bytes(d) == sum(a.nbytes for a in b.values())


def test_struct_layout_offsets_by_hand():
    """12 ints (48 bytes), then 8-byte pointers: x at 48, y at 56; act_dim follows cand_d; the
    reward terms' state closes the struct."""
    fields, size = schema.struct_layout()
    at = {name: (off, dt) for name, off, dt in fields}
    assert at["W"] == (0, None) and at["num_terms"] == (44, None)
    assert at["x"][0] == 48 and at["y"][0] == 56 and at["x"][1] == np.float32
    assert at["act_dim"][0] == at["cand_d"][0] + 8 and at["phys_dim"][0] == at["act_dim"][0] + 4
    # term_state_dim (4 bytes + 4 of padding) and the term_state pointer close the struct
    assert at["term_state_dim"][0] == at["phys_state"][0] + 8
    assert at["term_state"][0] == at["term_state_dim"][0] + 8 and size == at["term_state"][0] + 8


def test_struct_size_is_the_compiled_one():
    """sizeof(sd_sim) as the compiler laid it out equals the schema's layout (World checks the
    same at construction)."""
    from selfplaydrive._sim.reward import abi_sizes

    assert schema.struct_layout()[1] == abi_sizes()["sim"]


def _small_scenario():
    from helpers import make_scenario

    return make_scenario([{"xy": (0.0, 0.0), "waypoints": [(5.0, 0.0)]}], A=2, S=1, P=1, K=3, T=3)


def _small_dims() -> Dims:
    return Dims(W=1, A=2, S=1, P=1, K=3, T=3, G=2, max_obj=4, max_road=4, cand_cap=64, obs_dim=8)


def test_check_scenario_derives_shape_dtype_and_value_checks_from_the_table():
    from selfplaydrive.sim.buffers import check_scenario

    check_scenario(_small_scenario(), _small_dims(), 1)  # fits
    cases = [
        (
            "num_waypoints",
            np.array([1.0, 0.0]),
            r"num_waypoints: expected int values .* got dtype float64",
        ),
        ("agent_valid", np.array(["a", "b"]), r"scenario\.agent_valid: expected bool values"),
        ("hidden", np.ones((2, 2), np.float32), r"scenario\.hidden: expected shape \(2, 3\)"),
        ("ped_path", np.zeros((1, 4, 2), np.float32), r"scenario\.ped_path: expected shape \(1, 3, 2\)"),
        ("light_time_left", np.ones(1, np.float32), r"scenario\.light_time_left: expected shape \(0,\)"),
        (
            "agent_speed",
            np.array([np.nan, 0.0], np.float32),
            r"agent_speed: expected finite values .* slot 0",
        ),
    ]
    for name, value, match in cases:
        sc = _small_scenario()
        setattr(sc, name, value)
        with pytest.raises(ValueError, match=match):
            check_scenario(sc, _small_dims(), 1)


def test_every_scenario_row_names_a_scenario_field():
    from selfplaydrive.scenario.types import Scenario

    names = {f.name for f in dataclasses.fields(Scenario)}
    for f in schema.SCENARIO_FIELDS:
        assert f.name in names, f.name
        assert f.kind in schema.KINDS and f.check in ("", "finite", "size", "count", "points"), f.name
        assert not f.valid or f.valid in names, f.name
        if f.check == "points":
            assert f.bound in names, f.name
