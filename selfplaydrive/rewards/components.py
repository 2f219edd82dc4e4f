"""Reward terms as plug-in components (paper section 2.3; docs/components.md).

One contract, three forms. A term is either

- a `KernelTerm`: the address of a C function with the signature `sd_reward_term_fn` of
  selfplaydrive_abi.h (folder `selfplaydrive.get_include()`), called once per world inside the
  parallel step without the GIL. It comes from the library (the paper's eight terms), from a
  numba ``cfunc`` (`KernelTerm.from_numba`) or from a user's compiled Cython module
  (`KernelTerm.from_cython`); or
- a Python term (`RewardHook`: ``name`` and ``__call__(state) -> (N,)``), run after the
  kernels on read-only views. It may replace a registered term of the same name.

`LinearReward` names the selected terms and their weights; the env keeps one column per
selected term (`VecEnv.reward_terms`, `VecEnv.term_names`), the reward is the sum of the
weighted columns, and each column has its own episode sum (`pop_episode_stats()["terms"]`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import ModuleType
from typing import Any

import numpy as np

from selfplaydrive._abi_load import capsule_address, capsule_name, cython_capsule, numba_address
from selfplaydrive.errors import ConfigError
from selfplaydrive.rewards.base import MapBoundTerm
from selfplaydrive.rewards.registry import TERM_NAMES, TERMS, RewardHook

ABI_VERSION = 1  # SELFPLAYDRIVE_ABI_VERSION of selfplaydrive_abi.h
# the C signature of a reward component, as selfplaydrive_abi.h declares `sd_reward_term_fn`
SIGNATURE = (
    "void (const sd_sim *sim, const sd_params *prm, const sd_atlas *atlas, const float *args, "
    "int32_t w, float *out, int32_t stride)"
)


@dataclass(frozen=True, eq=False)
class KernelTerm:
    """A reward term compiled to machine code, called inside the parallel step.

    Attributes:
        name: Column name (`VecEnv.term_names`, episode statistics, the trainer's ``term/`` tags).
        address: Address of a function with the signature `SIGNATURE` (`sd_reward_term_fn`).
        args: The term's own parameters, passed to the function as ``const float* args``
            (float32; NULL when empty).
        form: Where the code comes from: "builtin", "numba", "cython" or "address".
        doc: One line for listings (`describe_terms`).
        owner: The object that owns the machine code (a numba cfunc, a module); kept alive
            with the term so the address stays valid.
        state_dim: Floats of per-agent memory the term owns in the env's ``term_state``
            buffer (0: none). A term with state reserves ``args[0]``: the env writes there the
            offset of its first column (`LinearReward.bind`; docs/components.md).

    `args` is a tuple of floats, or for large tables (a map-bound term's packed map data,
    `MapBoundTerm`) a read-only float32 array, kept as it is.
    """

    name: str
    address: int
    args: tuple[float, ...] | np.ndarray = ()
    form: str = "address"
    doc: str = ""
    owner: Any = field(default=None, repr=False, compare=False)
    state_dim: int = 0

    def __post_init__(self) -> None:
        _check_name(self.name)
        if not isinstance(self.address, int) or isinstance(self.address, bool) or self.address <= 0:
            raise ConfigError(
                f"reward term {self.name!r}: address must be a positive integer, got {self.address!r}"
            )
        object.__setattr__(self, "args", _checked_args(self.name, self.args))
        dim = self.state_dim
        if isinstance(dim, bool) or not isinstance(dim, (int, np.integer)) or dim < 0:
            raise ConfigError(f"reward term {self.name!r}: state_dim must be an integer >= 0, got {dim!r}")
        if dim > 0 and len(self.args) == 0:
            raise ConfigError(
                f"reward term {self.name!r}: a term with state (state_dim={dim}) reserves args[0] for "
                "its state offset; give at least one arg"
            )
        object.__setattr__(self, "state_dim", int(dim))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, KernelTerm):
            return NotImplemented
        return (self.name, self.address, self.form, self.doc, self.state_dim) == (
            other.name,
            other.address,
            other.form,
            other.doc,
            other.state_dim,
        ) and np.array_equal(np.asarray(self.args, np.float64), np.asarray(other.args, np.float64))

    def __hash__(self) -> int:
        return hash((self.name, self.address, self.form, len(self.args), self.state_dim))

    def with_args(self, *args: float) -> KernelTerm:
        """The same function with other parameters."""
        return KernelTerm(
            self.name, self.address, tuple(args), self.form, self.doc, self.owner, self.state_dim
        )

    def renamed(self, name: str) -> KernelTerm:
        """The same function and parameters under another column name."""
        return KernelTerm(name, self.address, self.args, self.form, self.doc, self.owner, self.state_dim)

    def with_state_offset(self, offset: int) -> KernelTerm:
        """This term with ``args[0]`` set to `offset`, the first of its ``term_state`` columns."""
        if self.state_dim == 0:
            return self
        if isinstance(self.args, np.ndarray):
            args: tuple[float, ...] | np.ndarray = self.args.copy()
            args[0] = offset  # type: ignore[index]
        else:
            args = (float(offset), *self.args[1:])
        return KernelTerm(self.name, self.address, args, self.form, self.doc, self.owner, self.state_dim)

    @classmethod
    def from_numba(cls, name: str, cfunc: Any, args: Sequence[float] = (), doc: str = "") -> KernelTerm:
        """A term from a numba ``@cfunc(selfplaydrive.rewards.numba_abi.SIGNATURE)``.

        Raises:
            ConfigError: `cfunc` is not a numba cfunc, or was compiled with another signature.
        """
        from selfplaydrive.rewards import numba_abi  # needs the numba extra

        what = f"reward term {name!r}"
        address = numba_address(what, cfunc, numba_abi.SIGNATURE, "numba_abi.SIGNATURE", SIGNATURE)
        return cls(name, address, tuple(args), "numba", doc or (cfunc.__doc__ or "").strip(), cfunc)

    @classmethod
    def from_cython(
        cls, name: str, module: ModuleType, function: str, args: Sequence[float] = (), doc: str = ""
    ) -> KernelTerm:
        """A term from a compiled Cython module that declares ``function`` in its ``.pxd`` with
        the types of selfplaydrive_abi.pxd (Cython then exports it in ``__pyx_capi__``).

        Raises:
            ConfigError: The module does not export `function`, or its signature differs.
        """
        capsule = cython_capsule(f"reward term {name!r}", module, function)
        return cls.from_capsule(name, capsule, args, doc or f"{module.__name__}.{function}", module)

    @classmethod
    def from_capsule(
        cls, name: str, capsule: Any, args: Sequence[float] = (), doc: str = "", owner: Any = None
    ) -> KernelTerm:
        """A term from a PyCapsule whose name is the function's C signature (Cython's
        ``__pyx_capi__`` convention, as `scipy.LowLevelCallable` reads it).

        Raises:
            ConfigError: Not a capsule, or a capsule of another signature.
        """
        want = _builtin_capsule_signature()
        address = capsule_address(f"reward term {name!r}", capsule, want, f"sd_reward_term_fn: {SIGNATURE}")
        return cls(name, address, tuple(args), "cython", doc, owner if owner is not None else capsule)


def _checked_args(name: str, args: object) -> tuple[float, ...] | np.ndarray:
    """`args` as a tuple of finite floats, or (an array) as a read-only float32 copy."""
    if isinstance(args, np.ndarray):
        arr = np.array(args, dtype=np.float32).reshape(-1)
        if not np.isfinite(arr).all():
            raise ConfigError(f"reward term {name!r}: args must be finite numbers, got a non-finite entry")
        arr.flags.writeable = False
        return arr
    try:
        out = tuple(float(a) for a in args)  # type: ignore[attr-defined]
    except (TypeError, ValueError):
        out = (math.nan,)
    if not all(math.isfinite(a) for a in out):
        raise ConfigError(f"reward term {name!r}: args must be finite numbers, got {args!r}")
    return out


Term = KernelTerm | RewardHook | MapBoundTerm


# the registry ------------------------------------------------------------------------------
@functools.lru_cache(maxsize=1)
def _paper_terms() -> dict[str, KernelTerm]:
    from selfplaydrive._sim import reward as kernels

    addresses = kernels.paper_term_addresses()
    return {
        t.name: KernelTerm(
            t.name, int(addresses[t.name]), (), "builtin", f"{t.formula} when {t.when}", kernels
        )
        for t in TERMS
    }


_REGISTRY: dict[str, Term] = {}
# installed packages offer terms under this entry-point group (name = term name, value = a
# term object or a factory returning one): `pip install` a term package and name it in
# `reward.terms`, no registration code (examples/speed_limit_cython/pyproject.toml)
ENTRY_POINT_GROUP = "selfplaydrive.reward_terms"


def _registry() -> dict[str, Term]:
    if not _REGISTRY:  # the kernels are imported at first use: this module stays cheap to import
        _REGISTRY.update(_paper_terms())
        from selfplaydrive.rewards.rules import RULE_TERMS  # issue #15: the rule terms, off by default

        _REGISTRY.update({t.name: t for t in RULE_TERMS})
        from selfplaydrive.rewards.shaping import shaping_terms  # issue #16: shaping, off by default

        _REGISTRY.update({t.name: t for t in shaping_terms()})
    return _REGISTRY


def _entry_points() -> dict[str, Any]:
    """Installed terms not loaded yet: name -> entry point."""
    from importlib.metadata import entry_points

    return {ep.name: ep for ep in entry_points(group=ENTRY_POINT_GROUP) if ep.name not in _registry()}


def _lookup(name: str) -> Term | None:
    """The registered term `name`, loading an installed one on first use; None if unknown."""
    reg = _registry()
    if name in reg:
        return reg[name]
    ep = _entry_points().get(name)
    if ep is None:
        return None
    try:
        obj = ep.load()
        term = obj if isinstance(obj, KernelTerm) or hasattr(obj, "name") else obj()
        _check_term(term)
    except Exception as exc:  # any failure of a third-party plug-in is reported as a config error
        raise ConfigError(f"reward term {name!r}: loading entry point {ep.value!r} failed: {exc}") from exc
    if isinstance(term, KernelTerm) and term.name != name:
        term = term.renamed(name)
    if term.name != name:
        raise ConfigError(f"reward term {name!r}: entry point {ep.value!r} gave a term named {term.name!r}")
    reg[name] = term
    return term


def register_term(term: Term, *, replace: bool = False) -> Term:
    """Make `term` selectable by name in `LinearReward` (and from the Hydra ``reward.terms``).

    Args:
        term: A `KernelTerm` or a Python term (``name`` and ``__call__(state) -> (N,)``).
        replace: Allow replacing a registered term of the same name.

    Returns:
        The term (so the call can decorate an assignment).

    Raises:
        ConfigError: A name already registered (without `replace`) or a malformed term.
    """
    _check_term(term)
    reg = _registry()
    if term.name in reg and not replace:
        raise ConfigError(f"reward term {term.name!r} is already registered; pass replace=True to replace it")
    reg[term.name] = term
    return term


def registered_terms() -> tuple[str, ...]:
    """Names `LinearReward` accepts without further arguments: the paper's eight first, then
    registered ones, then those installed packages offer (entry points, loaded on first use)."""
    return (*_registry(), *_entry_points())


def get_term(name: str) -> Term:
    """The registered term `name`.

    Raises:
        ConfigError: An unknown name, listing the registered ones.
    """
    term = _lookup(name)
    if term is None:
        raise ConfigError(
            f"reward term {name!r} is not registered; registered terms: {', '.join(registered_terms())}"
        )
    return term


# composition -------------------------------------------------------------------------------
@dataclass(frozen=True)
class TermColumn:
    """One column of the env's per-term reward buffer (what `LinearReward.columns` returns)."""

    name: str
    term: Term
    weight: float

    @property
    def native(self) -> bool:
        """Computed inside the parallel step (a `KernelTerm`, or a `MapBoundTerm` once bound),
        not in Python afterwards."""
        return isinstance(self.term, KernelTerm) or _is_map_bound(self.term)


class LinearReward:
    """The reward as a weighted sum of named terms (section 2.3), one column per term.

    Args:
        weights: Term name -> weight, in column order (default: the paper's eight terms, each
            with weight 1, which reproduces the paper's reward bit for bit). A name refers to
            `terms` first, then to the registry (`register_term`, installed entry points). A
            compiled term's parameters can be set with a mapping instead of the weight:
            ``{"speed_limit": {"weight": 1.0, "args": [0.01, 14.0]}}`` (Hydra:
            ``+reward.terms.speed_limit={weight:1.0,args:[0.01,14.0]}``).
        terms: Term objects used by name in `weights` without registering them; a term named
            like a registered one replaces it in this reward (e.g. a Python "collision").

    Raises:
        ConfigError: An unknown name (the message lists the valid ones), a weight that is not
            a finite number, two `terms` of one name, a malformed term or more than the
            `MAX_TERMS` columns the step supports.

    Example:
        >>> from selfplaydrive.rewards import LinearReward
        >>> LinearReward({"collision": 1.0, "offroad": 0.5}).names
        ('collision', 'offroad')
    """

    def __init__(
        self, weights: Mapping[str, float | Mapping[str, Any]] | None = None, terms: Sequence[Term] = ()
    ) -> None:
        local: dict[str, Term] = {}
        for t in terms:
            _check_term(t)
            if t.name in local:
                raise ConfigError(f"reward terms: two terms are named {t.name!r}")
            local[t.name] = t
        if weights is None:
            weights = {name: 1.0 for name in TERM_NAMES}
        if not isinstance(weights, Mapping) or not weights:
            raise ConfigError(
                f"reward weights: expected a non-empty mapping of term name -> weight, got {weights!r}"
            )
        columns = []
        for name, spec in weights.items():
            term = local.get(name) or _lookup(name)
            if term is None:
                valid = list(dict.fromkeys([*local, *registered_terms()]))
                raise ConfigError(f"reward term {name!r} is unknown; valid terms: {', '.join(valid)}")
            weight, term = _weight_and_args(name, spec, term)
            columns.append(TermColumn(str(name), term, weight))
        self.columns: tuple[TermColumn, ...] = tuple(columns)
        _check_width(len(self.columns))

    @property
    def names(self) -> tuple[str, ...]:
        """Column names, in order."""
        return tuple(c.name for c in self.columns)

    def with_hooks(self, hooks: Sequence[RewardHook]) -> LinearReward:
        """This reward with Python terms appended at weight 1 (`VecEnv(reward_hooks=...)`)."""
        out = LinearReward.__new__(LinearReward)
        extra = []
        for h in hooks:
            _check_term(h)
            if h.name in self.names or h.name in [e.name for e in extra]:
                raise ConfigError(f"reward hook {h.name!r}: a reward column of that name exists already")
            extra.append(TermColumn(h.name, h, 1.0))
        out.columns = self.columns + tuple(extra)
        _check_width(len(out.columns))
        return out

    def bind(self, maps: Sequence[Any]) -> LinearReward:
        """This reward for an env with `maps`: every map-bound term (`MapBoundTerm`) replaced
        by the `KernelTerm` its ``bind(maps)`` returns, and the ``term_state`` columns laid out
        (each term with state gets the next `state_dim` columns; ``args[0]`` holds their
        offset). `VecEnv` calls it at construction.

        Raises:
            ConfigError: A map-bound term's ``bind`` returned no `KernelTerm`.
        """
        out = LinearReward.__new__(LinearReward)
        columns, offset = [], 0
        for c in self.columns:
            term = c.term
            if _is_map_bound(term):
                term = term.bind(maps)  # type: ignore[union-attr]
                if not isinstance(term, KernelTerm):
                    got = type(term).__name__
                    raise ConfigError(f"reward term {c.name!r}: bind(maps) gave a {got}, not a KernelTerm")
            if isinstance(term, KernelTerm) and term.state_dim:
                term = term.with_state_offset(offset)
                offset += term.state_dim
            columns.append(TermColumn(c.name, term, c.weight))
        out.columns = tuple(columns)
        return out

    @property
    def term_state_dim(self) -> int:
        """Floats of reward-term state per agent slot (the env's ``term_state`` width)."""
        return sum(c.term.state_dim for c in self.columns if isinstance(c.term, KernelTerm))

    def plan(self) -> list[tuple[int, np.ndarray | None, float, int]]:
        """(address, float32 args or None, weight, native) per column for the step
        (`_sim.world.World`); address 0: no call for that column (a Python column, native 0,
        or one filled by a group call of an earlier column).

        Where the paper's eight built-in terms are selected next to each other in their order
        (the default), one call of the library's 8-column component writes all eight in a single
        pass over the world's agents instead of eight passes: same values, bit for bit, and the
        paper configuration costs what it cost before the components (docs/benchmarks.md).
        """
        out: list[tuple[int, np.ndarray | None, float, int]] = []
        for c in self.columns:
            if _is_map_bound(c.term):
                raise ConfigError(
                    f"reward term {c.name!r} needs the env's maps: call bind(maps) before plan()"
                )
            if isinstance(c.term, KernelTerm):
                args = np.ascontiguousarray(c.term.args, dtype=np.float32) if len(c.term.args) else None
                out.append((c.term.address, args, c.weight, 1))
            else:
                out.append((0, None, c.weight, 0))
        paper = [_paper_terms()[name] for name in TERM_NAMES]
        for k in range(len(self.columns) - len(paper) + 1):
            run = [c.term for c in self.columns[k : k + len(paper)]]
            if all(
                isinstance(t, KernelTerm) and t.address == p.address and not len(t.args)
                for t, p in zip(run, paper, strict=True)
            ):
                from selfplaydrive._sim.reward import paper_group_address

                out[k] = (int(paper_group_address()), None, out[k][2], 1)
                for j in range(k + 1, k + len(paper)):
                    out[j] = (0, None, out[j][2], 1)
                break
        return out

    def __repr__(self) -> str:
        return f"LinearReward({ {c.name: c.weight for c in self.columns} })"


def _weight_and_args(name: str, spec: object, term: Term) -> tuple[float, Term]:
    """The weight of a `weights` entry (a number, or {weight, args}) and the term with its args."""
    weight = spec
    if isinstance(spec, Mapping):
        unknown = set(spec) - {"weight", "args"}
        if unknown:
            raise ConfigError(
                f"reward term {name!r}: unknown keys {sorted(unknown)}; expected weight and args"
            )
        weight = spec.get("weight", 1.0)
        if "args" in spec:
            if not isinstance(term, KernelTerm) and not _is_map_bound(term):
                raise ConfigError(f"reward term {name!r}: args are for compiled terms (KernelTerm) only")
            args = spec["args"]
            if isinstance(args, (str, bytes)) or not isinstance(args, Sequence):
                raise ConfigError(f"reward term {name!r}: args must be a list of numbers, got {args!r}")
            term = term.with_args(*args)  # type: ignore[union-attr]
    if isinstance(weight, bool) or not isinstance(weight, (int, float, np.number)):
        raise ConfigError(f"reward weight of {name!r}: expected a number, got {weight!r}")
    if not math.isfinite(float(weight)):
        raise ConfigError(f"reward weight of {name!r}: expected a finite number, got {weight!r}")
    return float(weight), term


def describe_terms() -> list[tuple[str, str, str]]:
    """(name, form, description) of every registered term, for listings and docs."""
    out = []
    for name, t in _registry().items():
        if isinstance(t, KernelTerm):
            form, doc = t.form, t.doc
        elif _is_map_bound(t):
            form, doc = "map-bound", str(getattr(t, "doc", ""))
        else:
            form, doc = "python", (type(t).__doc__ or "").strip().split("\n")[0]
        out.append((name, form, doc))
    return out


# checks ------------------------------------------------------------------------------------
def _check_name(name: object) -> None:
    if not isinstance(name, str) or not name or "/" in name or name != name.strip():
        raise ConfigError(f"reward term name: expected a non-empty string without '/', got {name!r}")


def _is_map_bound(t: object) -> bool:
    """A map-bound term (`MapBoundTerm`): not itself a kernel, but it binds to one."""
    return not isinstance(t, KernelTerm) and callable(getattr(t, "bind", None))


def _check_term(t: object) -> None:
    if isinstance(t, KernelTerm):
        return
    if _is_map_bound(t):
        _check_name(getattr(t, "name", None))
        return
    name = getattr(t, "name", None)
    _check_name(name)
    if not callable(t):
        raise ConfigError(
            f"reward term {name!r}: expected a KernelTerm or a Python term with __call__(state) -> (N,), "
            f"got {type(t).__name__}"
        )


def _check_width(n: int) -> None:
    from selfplaydrive._sim.reward import max_terms

    if n > max_terms():
        raise ConfigError(f"reward: {n} term columns selected, the step supports at most {max_terms()}")


# capsules ------------------------------------------------------------------------------------
def _builtin_capsule_signature() -> str:
    """The signature string Cython gives a function of the ABI's type (the library's own
    collision term, compiled against the same declarations a user's module cimports)."""
    from selfplaydrive._sim import reward as kernels

    name = capsule_name(kernels.__pyx_capi__["term_collision"])
    assert name is not None
    return name
