"""Observation encoders as plug-in components (paper section 2.5; issue #13; docs/components.md
"Write an observation encoder").

An encoder writes every active agent's observation row and declares the row's layout (named
blocks with shapes, `ObsLayout`), which the models read. One contract, three forms:

- a `KernelEncoder`: the address of a C function with the signature `sd_encoder_fn` of
  selfplaydrive_abi.h, called once per world inside the parallel step without the GIL. It comes
  from the library (`PaperEncoder`, `PartialObsEncoder`), from a numba ``cfunc``
  (`KernelEncoder.from_numba`) or from a user's compiled Cython module (`from_cython`);
- a Python encoder (`PythonEncoder`: ``name``, ``layout``, ``radius`` and
  ``__call__(state) -> (N, obs_dim)``), run after the kernels on read-only views; it REPLACES the
  compiled encoder (the step then writes no observation).

Python observation hooks (`ObsHook`) still append columns after the encoder's.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import ModuleType
from typing import Any, Protocol, runtime_checkable

import numpy as np

from selfplaydrive._abi_load import capsule_address, capsule_name, cython_capsule, numba_address
from selfplaydrive.errors import ConfigError
from selfplaydrive.obs.config import ObsConfig
from selfplaydrive.obs.layout import ObsLayout

# the C signature of an encoder, as selfplaydrive_abi.h declares `sd_encoder_fn`
SIGNATURE = (
    "void (const sd_sim *sim, const sd_params *prm, const sd_atlas *atlas, const void *args, "
    "int32_t w, float *obs, int32_t stride)"
)


@dataclass(frozen=True, eq=False)
class KernelEncoder:
    """An observation encoder compiled to machine code, called inside the parallel step.

    Attributes:
        name: Name for listings and errors.
        address: Address of a function with the signature `SIGNATURE` (`sd_encoder_fn`).
        layout: The columns it writes (named blocks with shapes; models build from it); every
            value it writes lies in [-layout.bound, layout.bound] (the observation Box).
        radius: Observation radius [m]: `prm->obs_radius` and `prm->pos_scale`, and the radius of
            the road gather.
        args: The encoder's own parameters, passed as ``const void* args``: a C-contiguous NumPy
            array (any dtype, e.g. a structured record), a sequence of floats (packed as float32)
            or None (NULL).
        road_gather: Road segments the events stage gathers per agent into `road_idx` for the
            encoder (`sim->max_road`); default: the layout's road slots (at least 1).
        scratch: Floats of per-world scratch (`sim->cand_d`) the encoder needs.
        form: Where the code comes from: "builtin", "numba", "cython" or "address".
        doc: One line for listings.
        owner: The object that owns the machine code (kept alive with the encoder).
    """

    name: str
    address: int
    layout: ObsLayout
    radius: float = 100.0
    args: Any = None
    road_gather: int | None = None
    scratch: int = 0
    form: str = "address"
    doc: str = ""
    owner: Any = field(default=None, repr=False)

    def __post_init__(self) -> None:
        _check_common(self.name, self.layout, self.radius)
        if not isinstance(self.address, int) or isinstance(self.address, bool) or self.address <= 0:
            raise ConfigError(
                f"encoder {self.name!r}: address must be a positive integer, got {self.address!r}"
            )
        object.__setattr__(self, "args", _pack_args(self.name, self.args))
        gather = self.layout.max_road if self.road_gather is None else self.road_gather
        if isinstance(gather, bool) or not isinstance(gather, (int, np.integer)) or gather < 0:
            raise ConfigError(f"encoder {self.name!r}: road_gather must be an integer >= 0, got {gather!r}")
        object.__setattr__(self, "road_gather", max(int(gather), 1))
        if (
            isinstance(self.scratch, bool)
            or not isinstance(self.scratch, (int, np.integer))
            or self.scratch < 0
        ):
            raise ConfigError(f"encoder {self.name!r}: scratch must be an integer >= 0, got {self.scratch!r}")

    def plan(self) -> tuple[int, np.ndarray | None]:
        """(address, args) for the step (`_sim.world.World`)."""
        return int(self.address), self.args

    @classmethod
    def from_numba(
        cls, name: str, cfunc: Any, layout: ObsLayout, radius: float = 100.0, args: Any = None, **kw: Any
    ) -> KernelEncoder:
        """An encoder from a numba ``@cfunc(selfplaydrive.rewards.numba_abi.ENCODER_SIGNATURE)``
        (numba sees ``args`` as a float32 pointer).

        Raises:
            ConfigError: `cfunc` is not a numba cfunc, or was compiled with another signature.
        """
        from selfplaydrive.rewards import numba_abi  # needs the numba extra

        hint = "numba_abi.ENCODER_SIGNATURE"
        address = numba_address(f"encoder {name!r}", cfunc, numba_abi.ENCODER_SIGNATURE, hint, SIGNATURE)
        kw.setdefault("doc", (cfunc.__doc__ or "").strip())
        return cls(name, address, layout, radius, args, form="numba", owner=cfunc, **kw)

    @classmethod
    def from_cython(
        cls,
        name: str,
        module: ModuleType,
        function: str,
        layout: ObsLayout,
        radius: float = 100.0,
        args: Any = None,
        **kw: Any,
    ) -> KernelEncoder:
        """An encoder from a compiled Cython module that declares ``function`` in its ``.pxd``
        with the types of selfplaydrive_abi.pxd (exported in ``__pyx_capi__``).

        Raises:
            ConfigError: The module does not export `function`, or its signature differs.
        """
        what = f"encoder {name!r}"
        capsule = cython_capsule(what, module, function)
        address = capsule_address(what, capsule, _builtin_capsule_signature(), f"sd_encoder_fn: {SIGNATURE}")
        kw.setdefault("doc", f"{module.__name__}.{function}")
        return cls(name, address, layout, radius, args, form="cython", owner=module, **kw)


class PaperEncoder(KernelEncoder):
    """The paper's encoder (section 2.5): ego, the `max_objects` nearest bodies and the
    `max_road` nearest road segments within `radius`, in the layout of `ObsLayout`.

    Args:
        max_objects: Nearest other bodies observed (63 in the paper).
        max_road: Nearest road segments observed (200).
        radius: Observation radius [m] (100), also the position scale.

    Raises:
        ConfigError: Sizes below 1 or a radius that is not positive.
    """

    def __init__(self, max_objects: int = 63, max_road: int = 200, radius: float = 100.0) -> None:
        cfg = ObsConfig(max_objects, max_road, radius)  # validates, names the values
        from selfplaydrive._sim import observe

        super().__init__(
            "paper",
            int(observe.encoder_address()),
            ObsLayout(cfg.max_objects, cfg.max_road),
            float(cfg.radius),
            form="builtin",
            doc="ego, nearest objects and road segments (paper section 2.5)",
            owner=observe,
        )

    @property
    def config(self) -> ObsConfig:
        """The sizes as an `ObsConfig`."""
        return ObsConfig(self.layout.max_objects, self.layout.max_road, self.radius)


# record of PartialArgs in _sim/partial.pyx (same order, 48 bytes, no padding)
PARTIAL_ARGS_DTYPE = np.dtype(
    [
        ("salt", np.uint64),
        ("occlusion", np.int32),
        ("visible_fraction", np.float32),
        ("pos_std", np.float32),
        ("heading_std", np.float32),
        ("speed_std", np.float32),
        ("p_miss", np.float32),
        ("fp_rate", np.float32),
        ("fp_length", np.float32),
        ("fp_width", np.float32),
        ("reserved", np.float32),
    ],
    align=True,
)


class PartialObsEncoder(KernelEncoder):
    """Partial observability on top of the paper encoder (issue #15 item 5; same layout, so
    models and checkpoints work unchanged). Every effect is off by default: then the rows are
    the paper encoder's, bit for bit. docs/observation.md "Partial observability".

    Args:
        max_objects, max_road, radius: As `PaperEncoder`.
        occlusion: Hide objects occluded by nearer bodies, seen from the ego's centre.
        visible_fraction: An object is hidden when the part of its angular extent not covered
            by nearer bodies is below this fraction (in [0, 1]).
        pos_std: [m] Gaussian noise on each coordinate of an observed object's position.
        heading_std: [rad] Gaussian noise on its heading.
        speed_std: [m/s] Gaussian noise on its speed (clamped at 0).
        p_miss: Probability that an object (not hidden) is missed.
        fp_rate: Expected false positives per agent and step (Poisson), uniform in the disc
            of `radius`, random heading, standing.
        fp_length, fp_width: [m] Size of a false positive.
        seed: Mixed into each world's key: the encoder's own stream (the world's is untouched).

    Raises:
        ConfigError: A value out of range, naming the key, the value and the range.
    """

    def __init__(
        self,
        max_objects: int = 63,
        max_road: int = 200,
        radius: float = 100.0,
        occlusion: bool = False,
        visible_fraction: float = 0.2,
        pos_std: float = 0.0,
        heading_std: float = 0.0,
        speed_std: float = 0.0,
        p_miss: float = 0.0,
        fp_rate: float = 0.0,
        fp_length: float = 4.5,
        fp_width: float = 1.8,
        seed: int = 0,
    ) -> None:
        cfg = ObsConfig(max_objects, max_road, radius)
        from selfplaydrive._sim import partial

        if partial.args_size() != PARTIAL_ARGS_DTYPE.itemsize:  # pragma: no cover - build mismatch
            raise RuntimeError("PartialArgs of _sim/partial.pyx and PARTIAL_ARGS_DTYPE differ: rebuild")
        if not isinstance(occlusion, (bool, np.bool_)):
            raise ConfigError(f"obs.occlusion: expected true or false, got {occlusion!r}")
        _in_range("obs.visible_fraction", visible_fraction, 0.0, 1.0)
        for key, v in (
            ("pos_std", pos_std),
            ("heading_std", heading_std),
            ("speed_std", speed_std),
            ("fp_rate", fp_rate),
        ):
            _in_range(f"obs.{key}", v, 0.0, math.inf)
        _in_range("obs.p_miss", p_miss, 0.0, 1.0)
        _in_range("obs.fp_length", fp_length, 0.0, math.inf, low_open=True)
        _in_range("obs.fp_width", fp_width, 0.0, math.inf, low_open=True)
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed < 2**64:
            raise ConfigError(f"obs.seed: expected an integer in [0, 2**64), got {seed!r}")
        rec = np.zeros(1, dtype=PARTIAL_ARGS_DTYPE)
        rec["salt"] = np.uint64(int(seed))
        rec["occlusion"] = int(bool(occlusion))
        for key, v in (
            ("visible_fraction", visible_fraction),
            ("pos_std", pos_std),
            ("heading_std", heading_std),
            ("speed_std", speed_std),
            ("p_miss", p_miss),
            ("fp_rate", fp_rate),
            ("fp_length", fp_length),
            ("fp_width", fp_width),
        ):
            rec[key] = v
        self.params = {name: rec[name][0].item() for name in PARTIAL_ARGS_DTYPE.names or ()}
        super().__init__(
            "partial",
            int(partial.encoder_address()),
            ObsLayout(cfg.max_objects, cfg.max_road),
            float(cfg.radius),
            args=rec.view(np.uint8),
            scratch=int(partial.scratch_floats(cfg.max_objects)),
            form="builtin",
            doc="paper encoder with occlusion, perception noise, misses and false positives",
            owner=partial,
        )


@runtime_checkable
class PythonEncoder(Protocol):
    """An encoder in Python/NumPy: it replaces the compiled encoder (the step writes no
    observation) and runs after the step on read-only views of the state.

    Attributes:
        name: Name for errors.
        layout: The columns it returns (`ObsLayout`).
        radius: Observation radius [m] (the road gather's radius, `prm.obs_radius`).
    """

    name: str
    layout: ObsLayout
    radius: float

    def __call__(self, state: Any) -> np.ndarray:
        """(num_agents, layout.obs_dim) finite float32 rows; rows of slots that are neither
        active nor ended this step are ignored."""
        ...


Encoder = KernelEncoder | PythonEncoder


def as_encoder(obs: object) -> Encoder:
    """The encoder for `VecEnv(obs=...)`: None (the paper's), an `ObsConfig` (the paper encoder
    of those sizes), a `KernelEncoder` or a Python encoder.

    Raises:
        ConfigError: Anything else, or a Python encoder without a layout.
    """
    if obs is None:
        return PaperEncoder()
    if isinstance(obs, ObsConfig):
        return PaperEncoder(obs.max_objects, obs.max_road, obs.radius)
    if isinstance(obs, KernelEncoder):
        return obs
    if callable(obs) and hasattr(obs, "layout"):
        name = getattr(obs, "name", type(obs).__name__)
        _check_common(name, obs.layout, getattr(obs, "radius", None))
        return obs  # type: ignore[return-value]
    raise ConfigError(
        "obs: expected an ObsConfig, a KernelEncoder (PaperEncoder, PartialObsEncoder, from_numba, "
        f"from_cython) or a Python encoder (name, layout, radius, __call__(state)), got {type(obs).__name__}"
    )


def bind_encoder(encoder: Encoder, maps: Sequence[Any], atlas: Mapping[str, np.ndarray]) -> Encoder:
    """The encoder an env runs: ``encoder.bind(maps, atlas)`` when the encoder defines ``bind``
    (one whose rows depend on map data the atlas does not carry, e.g. `RulesEncoder`: which
    segments are STOP lines), else the encoder itself. `VecEnv` calls it once, when it is
    constructed, with its maps and `build_atlas(maps)` (sim/atlas.py: the atlas positions the
    road gather writes to `road_idx`); the bound encoder must keep the name, layout and radius.

    Raises:
        ConfigError: ``bind`` returned something else than an encoder of the same layout.
    """
    bind = getattr(encoder, "bind", None)
    if not callable(bind):
        return encoder
    bound = bind(maps, atlas)
    same = (
        getattr(bound, "name", None) == encoder.name
        and getattr(bound, "layout", None) == encoder.layout
        and getattr(bound, "radius", None) == encoder.radius
        and isinstance(bound, KernelEncoder) == isinstance(encoder, KernelEncoder)
    )
    if not same:
        raise ConfigError(
            f"encoder {encoder.name!r}: bind(maps, atlas) must return an encoder of the same name, "
            f"layout and radius, got {bound!r}"
        )
    return bound


# checks ------------------------------------------------------------------------------------
def _check_common(name: object, layout: object, radius: object) -> None:
    if not isinstance(name, str) or not name:
        raise ConfigError(f"encoder name: expected a non-empty string, got {name!r}")
    if not isinstance(layout, ObsLayout):
        raise ConfigError(f"encoder {name!r}: layout must be an ObsLayout, got {type(layout).__name__}")
    if isinstance(radius, bool) or not isinstance(radius, (int, float, np.number)) or not float(radius) > 0:
        raise ConfigError(f"encoder {name!r}: radius must be a number > 0 [m], got {radius!r}")


def _in_range(key: str, value: object, low: float, high: float, low_open: bool = False) -> None:
    ok = (
        isinstance(value, (int, float, np.number))
        and not isinstance(value, bool)
        and math.isfinite(float(value))
    )
    if ok:
        v = float(value)  # type: ignore[arg-type]
        ok = (v > low if low_open else v >= low) and v <= high
    if not ok:
        lo = "(" if low_open else "["
        raise ConfigError(f"{key}: expected a finite number in {lo}{low}, {high}], got {value!r}")


def _pack_args(name: str, args: object) -> np.ndarray | None:
    if args is None:
        return None
    if isinstance(args, np.ndarray):
        a = np.ascontiguousarray(args)
    elif isinstance(args, (bytes, bytearray)):
        a = np.frombuffer(bytes(args), dtype=np.uint8).copy()
    elif isinstance(args, Sequence) and not isinstance(args, str):
        try:
            a = np.asarray([float(v) for v in args], dtype=np.float32)
        except (TypeError, ValueError):
            raise ConfigError(
                f"encoder {name!r}: args must be numbers, bytes or an array, got {args!r}"
            ) from None
        if not np.all(np.isfinite(a)):
            raise ConfigError(f"encoder {name!r}: args must be finite numbers, got {args!r}")
    else:
        raise ConfigError(
            f"encoder {name!r}: args must be numbers, bytes or an array, got {type(args).__name__}"
        )
    if a.size == 0:
        return None
    a.flags.writeable = False
    return a


def _builtin_capsule_signature() -> str:
    """The signature string Cython gives a function of the encoder type (the library's own
    paper encoder, compiled against the same declarations a user's module cimports)."""
    from selfplaydrive._sim import observe

    name = capsule_name(observe.__pyx_capi__["encode_paper"])  # type: ignore[attr-defined]
    assert name is not None
    return name
