"""The spawner contract (paper section 2.2; docs/architecture.md "Protocols").

A spawner draws the initial state of one world, a `Scenario`, from a compiled `RoadMap` and a
seeded generator. `VecEnv` calls it at `reset` and at every autoreset, once per world, with that
world's own generator; `selfplaydrive.testing.check_spawner` checks an implementation.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol, runtime_checkable

if TYPE_CHECKING:
    import numpy as np

    from selfplaydrive.maps.roadmap import RoadMap
    from selfplaydrive.scenario.types import Scenario

__all__ = ["Spawner"]


@runtime_checkable
class Spawner(Protocol):
    """Anything with ``sample(road_map, rng, map_index=0) -> Scenario``.

    Contract every implementation keeps:

    - Every random draw comes from `rng` (DESIGN.md principle 7): no global generator, no
      clock, no generator of its own. The same map and generator state give the same
      `Scenario`, bit for bit, so a rollout replays from its seed and `VecEnv.get_state`
      (which saves the per-world generators, not the spawner) restores it exactly.
    - Slot counts are fixed per spawner: every call returns arrays of the same shapes
      (`Scenario` documents them); unused slots are marked invalid, never dropped.
    - Valid bodies do not overlap, waypoints and pedestrian paths are finite, and
      `episode_length` is positive (`selfplaydrive.sim.buffers.check_scenario`).
    - `map_index` is the index of `road_map` among the env's maps; it is stored in the
      `Scenario` unchanged.
    """

    def sample(self, road_map: RoadMap, rng: np.random.Generator, map_index: int = 0) -> Scenario:
        """Draw one world's initial state on `road_map` from `rng`."""
        ...
