"""Physics models as plug-in components (paper section 2.6; docs/components.md "Write a physics
model").

One contract, three forms, like the reward terms (rewards/components.py). A physics model is
either

- compiled: the address of a C function with the signature `sd_physics_fn` of
  selfplaydrive_abi.h (folder `selfplaydrive.get_include()`), called once per world inside the
  parallel step without the GIL. It comes from the library (`BicycleModel`,
  `FrictionBicycleModel`, `JerkBicycleModel`, `DeltaModel`), from a numba ``cfunc``
  (`KernelPhysics.from_numba`, signature `selfplaydrive.physics.numba_abi.SIGNATURE`) or from a
  user's compiled Cython module (`KernelPhysics.from_cython`); or
- Python/NumPy (slow path): an object with ``external = True`` and
  ``step(buffers, dt, accel, steer)`` that moves the vehicles before the kernels, which then skip
  their dynamics (`PymunkModel`).

Every model declares its action space (`PhysicsModel.actions`: a value table or box bounds,
with the names and units of the columns; None: the env's (acceleration, steering) actions of
section 2.4), its own parameters (`args`, float32, passed as ``const float* args``) and the
per-agent state it owns (`state_dim` floats per slot, in the env's ``phys_state`` buffer, zero at
spawn). `selfplaydrive.testing.check_physics` checks a model against the contract.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from types import ModuleType
from typing import TYPE_CHECKING, Any

import numpy as np

from selfplaydrive._abi_load import capsule_address, capsule_name, cython_capsule, numba_address
from selfplaydrive._targets import load_attr
from selfplaydrive.errors import ConfigError

if TYPE_CHECKING:  # sim/ imports this package (sim/vec_env.py): the action classes at use
    from selfplaydrive.sim.actions import BoxActions, DiscreteActions

    Actions = DiscreteActions | BoxActions

ABI_VERSION = 1  # SELFPLAYDRIVE_ABI_VERSION of selfplaydrive_abi.h
# the C signature of a physics component, as selfplaydrive_abi.h declares `sd_physics_fn`
SIGNATURE = "void (sd_sim *sim, const sd_params *prm, const float *args, int32_t w, float *state)"
PHYS_COMPONENT = 3  # SD_PHYS_COMPONENT: `Params.physics` of a model that is not the paper's


class PhysicsModel:
    """Base of the physics components: what `VecEnv` asks of a model.

    Subclasses set `name`, `kernel` and `max_speed` and implement `address` and `args`; a model
    with its own action space sets `actions`, one with per-agent state `state_dim`.

    Attributes:
        name: Short name (listings, error messages).
        kernel: `Params.physics` value (SD_PHYS_*; listings only, no kernel branches on it).
        max_speed: Speed clamp [m/s]; also the observation scale of speeds.
        actions: The model's own action space, or None for the env's (acceleration [m/s^2],
            steering [rad]) actions (discrete table or box, section 2.4).
        accepts: Action kinds the model reads: "discrete" (act_i, indices into the value
            tables) and/or "continuous" (act_f).
        state_dim: Floats of per-agent state the model owns (0: none).
        state_names: Name of each state column.
        external: True for a model stepped in Python before the kernels (slow path).
    """

    name = "physics"
    kernel = PHYS_COMPONENT
    max_speed = 40.0
    wheelbase_ratio = 0.6  # Params fields the paper's build had; kept filled for the ABI
    gravity = 9.81
    actions: Actions | None = None
    accepts: tuple[str, ...] = ("discrete", "continuous")
    state_dim = 0
    state_names: tuple[str, ...] = ()
    external = False

    def address(self) -> int:
        """Address of the model's `sd_physics_fn` (0 for a model stepped in Python)."""
        raise NotImplementedError

    def args(self) -> tuple[float, ...]:
        """The model's own parameters, in the order its function reads them."""
        return ()

    def physics_slot(self) -> tuple[int, np.ndarray | None]:
        """(address, float32 args or None) for `_sim.world.World`."""
        args = self.args()
        return int(self.address()), (np.asarray(args, dtype=np.float32) if args else None)

    def kernel_params(self) -> dict[str, object]:
        """The physics fields of the `Params` struct."""
        return {
            "physics": int(self.kernel),
            "wheelbase_ratio": float(self.wheelbase_ratio),
            "gravity": float(self.gravity),
            "max_speed": float(self.max_speed),
        }

    def resolve_actions(self, requested: Actions | None) -> Actions:
        """The env's action table: `requested` (checked against what the model reads), else
        the model's own, else the paper's discrete tables.

        Raises:
            ConfigError: `requested` is of a kind the model does not read, or has a number of
                columns other than the model's action space.
        """
        from selfplaydrive.sim.actions import DiscreteActions

        table = requested if requested is not None else self.actions
        if table is None:
            table = DiscreteActions()
        kind = "discrete" if table.discrete else "continuous"
        if kind not in self.accepts:
            raise ConfigError(
                f"physics {self.name!r}: reads {' or '.join(self.accepts)} actions, got {kind} "
                f"{type(table).__name__} (columns {getattr(table, 'names', '?')})"
            )
        want = self.actions.dim if self.actions is not None else 2
        if table.dim != want:
            raise ConfigError(
                f"physics {self.name!r}: expects {want} action columns"
                f"{' ' + str(self.actions.names) if self.actions is not None else ''}, got {table.dim}"
            )
        if self.actions is not None and tuple(table.names) != tuple(self.actions.names):
            # e.g. the paper's acceleration table given to a model that reads changes of it
            raise ConfigError(
                f"physics {self.name!r}: reads actions {tuple(self.actions.names)}, got a table of "
                f"{tuple(table.names)}; set the model's own tables in its parameters (physics.model)"
            )
        return table

    def describe(self) -> str:
        """One line: the model, its action columns and units, its state."""
        acts = self.actions
        cols = (
            ", ".join(f"{n} [{u}]" for n, u in zip(acts.names, acts.units, strict=True))
            if acts
            else ("accel [m/s^2], steer [rad] (the env's actions)")
        )
        state = f"; state: {', '.join(self.state_names)}" if self.state_dim else ""
        return f"{self.name}: actions {cols}{state}"


class KernelPhysics(PhysicsModel):
    """A physics model compiled to machine code (numba cfunc, Cython, or any C address).

    Args:
        name: Short name.
        address: Address of a function with the signature `SIGNATURE` (`sd_physics_fn`).
        args: The model's parameters, passed as ``const float* args`` (float32; NULL when empty).
        actions: Its action space (None: the env's (acceleration, steering) actions).
        accepts: Action kinds the function reads ("discrete", "continuous").
        state_dim: Floats of per-agent state it owns (``float* state``: the world's (A, state_dim)
            rows, zero at spawn).
        state_names: Names of the state columns.
        max_speed: The speed clamp the model keeps [m/s] (observation scale of speeds).
        form: "numba", "cython" or "address".
        doc: One line for listings.
        owner: The object owning the machine code, kept alive with the model.

    Raises:
        ConfigError: A bad address, non-finite args, state names not matching state_dim, or a
            non-positive max_speed.
    """

    def __init__(
        self,
        name: str,
        address: int,
        args: Sequence[float] = (),
        actions: Actions | None = None,
        accepts: Sequence[str] = ("discrete", "continuous"),
        state_dim: int = 0,
        state_names: Sequence[str] = (),
        max_speed: float = 40.0,
        form: str = "address",
        doc: str = "",
        owner: Any = None,
    ) -> None:
        if not isinstance(name, str) or not name:
            raise ConfigError(f"physics model name: expected a non-empty string, got {name!r}")
        if not isinstance(address, int) or isinstance(address, bool) or address <= 0:
            raise ConfigError(f"physics model {name!r}: address must be a positive integer, got {address!r}")
        try:
            fargs = tuple(float(a) for a in args)
        except (TypeError, ValueError):
            fargs = (math.nan,)
        if not all(math.isfinite(a) for a in fargs):
            raise ConfigError(f"physics model {name!r}: args must be finite numbers, got {args!r}")
        bad = set(accepts) - {"discrete", "continuous"}
        if bad or not accepts:
            raise ConfigError(
                f"physics model {name!r}: accepts must name 'discrete' and/or 'continuous', got {accepts!r}"
            )
        if isinstance(state_dim, bool) or not isinstance(state_dim, int) or not 0 <= state_dim <= 64:
            raise ConfigError(
                f"physics model {name!r}: state_dim: expected an integer in [0, 64], got {state_dim!r}"
            )
        names = tuple(state_names) or tuple(f"s{k}" for k in range(state_dim))
        if len(names) != state_dim:
            raise ConfigError(
                f"physics model {name!r}: state_names: expected {state_dim} names, got {list(state_names)}"
            )
        if not (0 < float(max_speed) < 200):
            raise ConfigError(f"physics model {name!r}: max_speed: expected (0, 200) m/s, got {max_speed!r}")
        self.name = name
        self._address = address
        self._args = fargs
        self.actions = actions
        self.accepts = tuple(accepts)
        self.state_dim = state_dim
        self.state_names = names
        self.max_speed = float(max_speed)
        self.form = form
        self.doc = doc
        self.owner = owner

    def address(self) -> int:
        return self._address

    def args(self) -> tuple[float, ...]:
        return self._args

    def __repr__(self) -> str:
        return f"KernelPhysics({self.name!r}, form={self.form!r}, args={self._args})"

    @classmethod
    def from_numba(cls, name: str, cfunc: Any, **kwargs: Any) -> KernelPhysics:
        """A model from a numba ``@cfunc(selfplaydrive.physics.numba_abi.SIGNATURE)``; keyword
        arguments as the constructor's (args, actions, accepts, state_dim, ...).

        Raises:
            ConfigError: `cfunc` is not a numba cfunc, or was compiled with another signature.
        """
        from selfplaydrive.physics import numba_abi  # needs the numba extra

        what, hint = f"physics model {name!r}", "physics.numba_abi.SIGNATURE"
        address = numba_address(what, cfunc, numba_abi.SIGNATURE, hint, SIGNATURE)
        kwargs.setdefault("doc", (cfunc.__doc__ or "").strip().split("\n")[0])
        return cls(name, address, form="numba", owner=cfunc, **kwargs)

    @classmethod
    def from_cython(cls, name: str, module: ModuleType, function: str, **kwargs: Any) -> KernelPhysics:
        """A model from a compiled Cython module that declares ``function`` in its ``.pxd`` with
        the types of selfplaydrive_abi.pxd (Cython exports it in ``__pyx_capi__``).

        Raises:
            ConfigError: The module does not export `function`, or its signature differs.
        """
        capsule = cython_capsule(f"physics model {name!r}", module, function)
        kwargs.setdefault("doc", f"{module.__name__}.{function}")
        kwargs.setdefault("owner", module)
        return cls.from_capsule(name, capsule, **kwargs)

    @classmethod
    def from_capsule(cls, name: str, capsule: Any, **kwargs: Any) -> KernelPhysics:
        """A model from a PyCapsule named by the function's C signature (Cython's convention).

        Raises:
            ConfigError: Not a capsule, or a capsule of another signature.
        """
        what, c_name = f"physics model {name!r}", f"sd_physics_fn: {SIGNATURE}"
        address = capsule_address(what, capsule, builtin_capsule_signature(), c_name)
        kwargs.setdefault("form", "cython")
        kwargs.setdefault("owner", capsule)
        return cls(name, address, **kwargs)


def builtin_capsule_signature() -> str:
    """The signature string Cython gives a function of type `sd_physics_fn` (the library's own
    bicycle, compiled against the declarations a user's module cimports)."""
    from selfplaydrive._sim import physics as kernels

    name = capsule_name(kernels.__pyx_capi__["phys_bicycle"])
    assert name is not None
    return name


def load_physics(target: str, **kwargs: Any) -> Any:
    """The physics model named by `target`: ``"package.module:attr"`` or
    ``"path/to/file.py:attr"``; `attr` is a model or a factory called with `kwargs`. Lets Hydra
    select a model defined outside the package in one override
    (``physics=custom physics.model.target=examples/10_physics_numba.py:unicycle``).

    Raises:
        ConfigError: A malformed target, a module or attribute that does not exist, or an
            object that is not a physics model.
    """
    obj = load_attr(target, "physics.model.target", "physics")
    attr = str(target).rsplit(":", 1)[1]
    model = obj(**kwargs) if callable(obj) and not _is_model(obj) else obj
    if kwargs and model is obj:
        raise ConfigError(
            f"physics.model.target {target!r}: {attr!r} is a model, not a factory; "
            f"it takes no {sorted(kwargs)}"
        )
    if not _is_model(model):
        raise ConfigError(
            f"physics.model.target {target!r}: expected a physics model (physics_slot(), kernel_params()) "
            f"or a factory of one, got {type(model).__name__}"
        )
    return model


def _is_model(obj: object) -> bool:
    return not isinstance(obj, type) and hasattr(obj, "physics_slot") and hasattr(obj, "kernel_params")


__all__ = [
    "ABI_VERSION",
    "SIGNATURE",
    "KernelPhysics",
    "PhysicsModel",
    "builtin_capsule_signature",
    "load_physics",
]
