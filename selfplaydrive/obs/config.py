"""Observation configuration and the contract of extra observation features in Python."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from selfplaydrive.errors import ConfigError


@dataclass(frozen=True)
class ObsConfig:
    """How many objects and road segments each agent observes, and within what radius.

    Attributes:
        max_objects: Nearest other bodies observed (63 in the paper).
        max_road: Nearest road segments observed (200 in the paper).
        radius: Observation radius [m] (100 in the paper); also the position scale.
    """

    max_objects: int = 63
    max_road: int = 200
    radius: float = 100.0

    def __post_init__(self) -> None:
        if self.max_objects < 1 or self.max_road < 1 or not self.radius > 0:
            raise ConfigError(f"obs: expected max_objects >= 1, max_road >= 1, radius > 0, got {self}")


class ObsHook(Protocol):
    """Extra observation columns computed in Python after the kernels.

    Attributes:
        name: Feature block name.
        dim: Number of columns appended to each observation row.
    """

    name: str
    dim: int

    def __call__(self, state: object) -> np.ndarray:
        """Return (num_agents, dim) float32 features from read-only views of the env state."""
        ...
