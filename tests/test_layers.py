"""Layers flow one way (docs/architecture.md "Layers"): a module imports only from its own
layer and the ones below. Checked on the import statements of every module (nested and
TYPE_CHECKING imports included) and on the cimports of the spawner's Cython kernels."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "selfplaydrive"
SIM = PKG / "_sim"

UPPER = (
    "sim",
    "env",
    "models",
    "trainers",
    "eval",
    "render",
    "drivers",
    "policies",
    "builder",
    "hydra_app",
    "cli",
)
# package -> subpackages / modules of selfplaydrive it must not import
FORBIDDEN = {
    "maps": ("scenario", "rewards", "physics", "obs", "testing", *UPPER),
    "scenario": UPPER,
    "physics": ("scenario", *UPPER),
    "rewards": ("scenario", *UPPER),
    "obs": ("scenario", *UPPER),
    "models": ("scenario", "physics", "rewards", *UPPER),  # networks over the observation layout
    "eval": ("hydra_app", "cli"),
}
# the Cython kernels each layer may import: the map layer only the map-level ones
ALLOWED_SIM = {
    "maps": {"lanes", "spatial"},
    "scenario": {"lanes", "spatial", "placement", "chunks", "waypoints", "pedestrians", "samplers"},
}
# known exceptions, each with its reason
EXCEPTIONS = {
    # the observation layout (named blocks the models build from) lives in sim/layout.py until
    # the observation-encoder work moves it to obs/layout.py (issue #13)
    ("models", "sim.layout"),
    ("obs", "sim.layout"),
    # a physics model declares its action space (issue #13); the action-table types it builds
    # (DiscreteActions, BoxActions) still live in sim/actions.py, next to the env's checks
    ("physics", "sim.actions"),
}


def imports(path: Path) -> set[str]:
    """selfplaydrive modules imported anywhere in `path`, without the `selfplaydrive.` prefix."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        names = [node.module or ""] if isinstance(node, ast.ImportFrom) else []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        out |= {n.removeprefix("selfplaydrive.") for n in names if n.startswith("selfplaydrive.")}
    return out


def modules(layer: str) -> list[Path]:
    # a package's `__main__` is an entry point (a command on top of every layer), not a layer
    return sorted(p for p in (PKG / layer).rglob("*.py") if p.name != "__main__.py")


@pytest.mark.parametrize("layer", sorted(FORBIDDEN))
def test_layer_imports_nothing_above_it(layer):
    bad = []
    for path in modules(layer):
        for name in imports(path):
            top = name.split(".")[0]
            if (layer, name) in EXCEPTIONS:
                continue
            if top in FORBIDDEN[layer] and top != layer:
                bad.append(f"{path.relative_to(ROOT)} imports selfplaydrive.{name}")
            if top == "_sim" and layer in ALLOWED_SIM and name.split(".")[1] not in ALLOWED_SIM[layer]:
                bad.append(f"{path.relative_to(ROOT)} imports selfplaydrive.{name} (a higher layer's kernel)")
    assert not bad, "\n".join(bad)


def test_lane_kernels_do_not_depend_on_the_spawner():
    spawner = ("spawn_common", "placement", "chunks", "waypoints", "pedestrians", "samplers")
    for path in (SIM / "lanes.pyx", SIM / "lanes.pxd"):
        text = path.read_text()
        for name in spawner:
            assert f"_sim.{name}" not in text, f"{path.name} refers to _sim.{name}"


def test_eval_app_and_hydra_app_do_not_import_each_other():
    assert not any(n.startswith("hydra_app") for n in imports(PKG / "eval" / "app.py"))
    # the command layer calls into evaluation, one way
    assert "eval.app" in imports(PKG / "hydra_app.py")


def test_policy_loading_lives_outside_render():
    shim = PKG / "render" / "policies.py"
    defs = [n for n in ast.parse(shim.read_text()).body if isinstance(n, (ast.FunctionDef, ast.ClassDef))]
    assert not defs, "render/policies.py only re-exports selfplaydrive.policies for old imports"
    users = [p for p in PKG.rglob("*.py") if p != shim and "render.policies" in imports(p)]
    assert not users, f"import selfplaydrive.policies instead: {users}"
