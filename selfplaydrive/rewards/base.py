"""The reward contracts (paper section 2.3; docs/components.md "Write a reward term").

A reward term comes in two forms: compiled (`KernelTerm`, the C signature `sd_reward_term_fn`
of selfplaydrive_abi.h, called inside the parallel step) or Python (`RewardHook`, called after
the step on read-only views). `RewardModule` is what the env needs from the composition of
terms, `LinearReward`. (`RewardTerm` names the description record of a built-in term,
rewards/registry.py.) `selfplaydrive.testing.check_reward_term` checks a term of either form.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Protocol, runtime_checkable

if TYPE_CHECKING:
    import numpy as np

    from selfplaydrive.maps.roadmap import RoadMap
    from selfplaydrive.rewards.components import KernelTerm

__all__ = ["MapBoundTerm", "RewardHook", "RewardModule"]


@runtime_checkable
class RewardHook(Protocol):
    """A reward term computed in Python after the kernels (the Python form of a term; it may
    replace a registered term of the same name in a `LinearReward`).

    Contract: the output is (num_agents,) finite float32 for the slots that acted (other rows
    are ignored); it reads the state only (the views are read-only) and is deterministic.

    Attributes:
        name: Column name in `VecEnv.term_names` / `reward_terms` and in the episode statistics.
    """

    name: str

    def __call__(self, state: object) -> np.ndarray:
        """Return the (num_agents,) float32 term from read-only views of the env state
        (`VecEnv.state`: arrays named as in sim/buffers.py). Rows of inactive slots are ignored."""
        ...


@runtime_checkable
class RewardModule(Protocol):
    """Named reward columns and the plan the step runs them by (`LinearReward`).

    ``plan()`` gives per column (address of an `sd_reward_term_fn` or 0, float32 args or None,
    weight, 1 if the step fills the column else 0); the env sums weight x term over the columns.
    """

    @property
    def names(self) -> tuple[str, ...]:
        """Column names, in order (`VecEnv.term_names`)."""
        ...

    def with_hooks(self, hooks: Sequence[RewardHook]) -> RewardModule:
        """This reward with Python terms appended at weight 1."""
        ...

    def plan(self) -> list[tuple[int, np.ndarray | None, float, int]]:
        """One (address, args, weight, native) per column, in order."""
        ...


@runtime_checkable
class MapBoundTerm(Protocol):
    """A compiled reward term that needs the env's map data (issue #15; docs/components.md
    "Map-bound terms"): junction zones, stop lines, crosswalk polygons, lane segments.

    It is registered and selected by name like any term; the env calls ``bind(maps)`` once at
    construction (`LinearReward.bind`) and steps the `KernelTerm` it returns, whose float32
    args pack the per-map tables after a small header (rewards/rule_tables.py).

    Attributes:
        name: Column name.
        doc: One line for listings.
    """

    name: str
    doc: str

    def bind(self, maps: Sequence[RoadMap]) -> KernelTerm:
        """The kernel term for an env whose world w plays ``maps[map_id[w]]``."""
        ...
