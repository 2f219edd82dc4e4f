"""The eight reward terms of section 2.3, in their default column order of the per-term buffer.

The kernels compute them (_sim/reward.pyx, as components of the ABI in selfplaydrive_abi.h);
this module names and documents them. `RewardHook`, the contract of terms written in Python
(run after the kernels on read-only views), lives in rewards/base.py and is importable from
here as before. rewards/components.py holds the registry of selectable terms and `LinearReward`.
"""

from __future__ import annotations

from dataclasses import dataclass

from selfplaydrive.rewards.base import RewardHook as RewardHook  # its home before rewards/base.py

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
