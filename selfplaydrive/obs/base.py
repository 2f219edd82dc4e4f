"""The observation-encoder contract (paper section 2.5; docs/architecture.md "Protocols").

An encoder writes every active agent's observation row and declares the row's layout (named
blocks with shapes, which the models build from). The paper's encoder is the library's
compiled one, sized by `ObsConfig`; extra Python columns come from `ObsHook`s.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol, runtime_checkable

if TYPE_CHECKING:
    from selfplaydrive.sim.layout import ObsLayout

__all__ = ["ObservationEncoder"]


@runtime_checkable
class ObservationEncoder(Protocol):
    """Anything with a ``name``, a ``layout`` and a ``radius`` [m].

    Contract every implementation keeps:

    - ``layout.obs_dim`` columns per row; every value it writes is finite and lies within the
      layout's bounds (the observation Box), and rows of inactive slots are left to the env.
    - It writes only its own block of the observation buffer, depends on nothing but the
      state of the agent's own world, and is deterministic (any thread count).
    - ``radius`` is the observation radius: the road gather and the position scale.
    """

    # read-only properties: a frozen dataclass's fields satisfy them too
    @property
    def name(self) -> str:
        """Name for listings and errors."""
        ...

    @property
    def radius(self) -> float:
        """Observation radius [m]."""
        ...

    @property
    def layout(self) -> ObsLayout:
        """The columns it writes, as named blocks (sim/layout.py)."""
        ...
