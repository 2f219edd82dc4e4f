"""The eight reward terms of section 2.3, in their default column order of the per-term buffer.

The kernels compute them (_sim/reward.pyx, as components of the ABI in selfplaydrive_abi.h);
this module names and documents them, and `RewardHook` is the contract of terms written in
Python, which run after the kernels on read-only views. rewards/components.py holds the
registry of selectable terms and `LinearReward`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

# Per-episode event counters of `VecEnv.pop_episode_stats()` (the kernels' `ev_count` order);
# pure Python so a saved recording can be drawn without the simulator.
EVENT_NAMES = (
    "collision",
    "pedestrian_collision",
    "offroad",
    "red_light",
    "waypoint",
    "comfort",
    "terminated",
    "truncated",
)


@dataclass(frozen=True)
class RewardTerm:
    """One named term: `formula` in the paper's notation, `when` it is given."""

    name: str
    formula: str
    when: str


TERMS = (
    RewardTerm("waypoint", "R = 0.25", "distance to the current waypoint < D (then the next one is current)"),
    RewardTerm("collision", "R = -C_collision (1 + 0.1 v)", "box overlaps a vehicle, obstacle or pedestrian"),
    RewardTerm("offroad", "R = -C_offroad (1 + 0.1 v)", "box touches a road-edge segment"),
    RewardTerm("red_light", "R = -C_red", "box touches, or the centre crossed, a red traffic-light line"),
    RewardTerm("comfort", "R = -C_comfort", "|a_long| > 3 or |a_lat| > 3 m/s^2"),
    RewardTerm("center", "R = C_center (-|B - s| + 0.05 / exp(|B - s| - 0.5))", "|alpha| < 60 deg"),
    RewardTerm(
        "align", "R = C_align (min(cos alpha, 0) + 0.0025 (1 - |alpha| / (pi / 2)))", "a lane is associated"
    ),
    RewardTerm("velocity", "R = 2.5e-4 max(cos alpha, 0)", "v >= 2.5 m/s and a lane is associated"),
)
TERM_NAMES = tuple(t.name for t in TERMS)


class RewardHook(Protocol):
    """A reward term computed in Python after the kernels (the Python form of a term; it may
    replace a registered term of the same name in a `LinearReward`).

    Attributes:
        name: Column name in `VecEnv.term_names` / `reward_terms` and in the episode statistics.
    """

    name: str

    def __call__(self, state: object) -> np.ndarray:
        """Return the (num_agents,) float32 term from read-only views of the env state
        (`VecEnv.state`: arrays named as in sim/buffers.py). Rows of inactive slots are ignored."""
        ...
