"""Every third-party module the package imports is declared in pyproject.toml.

A module imported by `selfplaydrive` must be the standard library, the package itself, a core
dependency, or an optional one imported inside ``with requires_extra("X"):`` where extra X of
pyproject.toml provides it (torch: ``requires_extra("torch")``, a separate install step). This
is what a fresh venv sees; the developers' interpreters hold packages installed by hand, which
is how an undeclared scipy once passed CI while a new user's install failed.
"""

from __future__ import annotations

import ast
import importlib.metadata as md
import re
import sys
from pathlib import Path

import pytest

from selfplaydrive._optional import requires_extra
from selfplaydrive.errors import MissingExtraError

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "selfplaydrive"
# modules of the Cython language and runtime, not distributions
CYTHON_NAMES = {"cython", "libc", "libcpp", "cpython", "openmp", "posix"}
# imports whose distribution differs from the one owning the top-level name
SUBMODULE_DISTS = {"torch.utils.tensorboard": "tensorboard"}
# import name -> distribution, for names the installed metadata may not know (not installed here)
KNOWN_DISTS = {
    "PIL": "pillow",
    "yaml": "pyyaml",
    "stable_baselines3": "stable-baselines3",
    "imageio_ffmpeg": "imageio-ffmpeg",
    "omegaconf": "omegaconf",
    "hydra": "hydra-core",
    "torch": "torch",
    "tensorboard": "tensorboard",
    "pettingzoo": "pettingzoo",
    "pymunk": "pymunk",
    "imageio": "imageio",
    "numba": "numba",
}


def _norm(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def _req_name(req: str) -> str:
    return _norm(re.split(r"[<>=!~;\[ ]", req.strip(), maxsplit=1)[0])


def _pyproject() -> dict:
    try:
        import tomllib
    except ImportError:  # Python 3.10
        pytest.skip("tomllib needs Python >= 3.11")
    return tomllib.loads((ROOT / "pyproject.toml").read_text())


def _declared() -> tuple[set[str], dict[str, set[str]]]:
    project = _pyproject()["project"]
    core = {_req_name(r) for r in project["dependencies"]}
    extras = {k: {_req_name(r) for r in v} for k, v in project["optional-dependencies"].items()}
    return core, extras


def _dist_of(module: str) -> str:
    for prefix, dist in SUBMODULE_DISTS.items():
        if module == prefix or module.startswith(prefix + "."):
            return dist
    top = module.split(".")[0]
    if top in KNOWN_DISTS:
        return KNOWN_DISTS[top]
    dists = md.packages_distributions().get(top)
    if dists:
        return _norm(dists[0])
    return _norm(top)


def _extra_of(node: ast.AST, parents: dict[ast.AST, ast.AST]) -> list[str] | None:
    """The extras named by every `with requires_extra("X")` block around `node`; None inside
    `if TYPE_CHECKING:` (never imported at run time)."""
    out = []
    while node in parents:
        node = parents[node]
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            return None
        if isinstance(node, ast.With):
            for item in node.items:
                call = item.context_expr
                if (
                    isinstance(call, ast.Call)
                    and getattr(call.func, "id", getattr(call.func, "attr", None)) == "requires_extra"
                    and call.args
                    and isinstance(call.args[0], ast.Constant)
                ):
                    out.append(str(call.args[0].value))
    return out


def _imports_py(path: Path) -> list[tuple[int, str, list[str]]]:
    tree = ast.parse(path.read_text(), str(path))
    parents = {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module]
        else:
            continue
        extras = _extra_of(node, parents)
        if extras is not None:
            found.extend((node.lineno, name, extras) for name in names)
    return found


def _imports_pyx(path: Path) -> list[tuple[int, str, list[str]]]:
    found = []
    for i, line in enumerate(path.read_text().splitlines(), 1):
        m = re.match(r"\s*(?:from\s+([\w.]+)\s+import(?!\s*\*?\s*$)|import\s+([\w.]+))", line)
        if m and not re.match(r"\s*(from\s+[\w.]+\s+)?cimport", line):
            found.append((i, m.group(1) or m.group(2), []))
    return found


def _third_party_imports() -> list[tuple[str, int, str, list[str]]]:
    out = []
    for path in sorted(PACKAGE.rglob("*.py")) + sorted(PACKAGE.rglob("*.pyx")):
        rel = str(path.relative_to(ROOT))
        imports = _imports_py(path) if path.suffix == ".py" else _imports_pyx(path)
        for line, name, extras in imports:
            top = name.split(".")[0]
            if top in sys.stdlib_module_names or top in CYTHON_NAMES | {"selfplaydrive", "__future__"}:
                continue
            out.append((rel, line, name, extras))
    return out


def test_the_walk_finds_the_imports_it_must_judge() -> None:
    names = {name.split(".")[0] for _, _, name, _ in _third_party_imports()}
    # a walk that finds nothing passes vacuously; these are imported in known places
    assert {"numpy", "torch", "shapely", "scipy", "gymnasium"} <= names


def test_every_third_party_import_is_declared() -> None:
    core, extras = _declared()
    bad = []
    for rel, line, name, extras_around in _third_party_imports():
        dist = _dist_of(name)
        if dist in core:
            continue
        if any((e == "torch" and dist == "torch") or dist in extras.get(e, ()) for e in extras_around):
            continue
        if extras_around:
            why = f"inside requires_extra({extras_around}), whose extras do not provide {dist!r}"
        else:
            owners = sorted(k for k, v in extras.items() if dist in v and k not in ("dev", "all"))
            owners = ["torch"] if dist == "torch" else owners
            why = (
                f"not a core dependency; import it inside `with requires_extra({owners[0]!r}):`"
                if owners
                else "declared nowhere in pyproject.toml"
            )
        bad.append(f"{rel}:{line}: import {name} (distribution {dist!r}): {why}")
    assert not bad, "undeclared imports:\n" + "\n".join(bad)


def test_requires_extra_names_extras_that_exist() -> None:
    _, extras = _declared()
    named = {e for _, _, _, around in _third_party_imports() for e in around}
    unknown = named - set(extras) - {"torch"}
    assert not unknown, f"requires_extra names extras missing from pyproject.toml: {sorted(unknown)}"


def test_all_extra_holds_every_optional_extra() -> None:
    _, extras = _declared()
    union = set().union(*(v for k, v in extras.items() if k not in ("all", "dev")))
    assert extras["all"] == union
    assert "torch" not in extras["all"]  # a bare torch requirement pulls the CUDA build


def test_missing_extra_says_what_to_install() -> None:
    with pytest.raises(MissingExtraError, match=r"selfplaydrive\[sb3\]"):
        with requires_extra("sb3"):
            import selfplaydrive_no_such_module
    with pytest.raises(MissingExtraError, match="torch"):
        with requires_extra("torch"):
            import selfplaydrive_no_such_module  # noqa: F401


def test_the_checker_catches_an_undeclared_import(tmp_path: Path) -> None:
    src = tmp_path / "m.py"
    src.write_text(
        "import numpy\nimport foo_undeclared\nfrom selfplaydrive._optional import requires_extra\n"
        "with requires_extra('sb3'):\n    import stable_baselines3\n"
    )
    found = {name: extras for _, name, extras in _imports_py(src)}
    assert found["foo_undeclared"] == []
    assert found["stable_baselines3"] == ["sb3"]
    core, _ = _declared()
    assert _dist_of("foo_undeclared") not in core
