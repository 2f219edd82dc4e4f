"""RL-library adapters over the native `selfplaydrive.sim.VecEnv` (docs/interfaces/).

- `GymVectorEnv`: `gymnasium.vector.VectorEnv`, one sub-env per agent slot (same-step autoreset).
- `SingleAgentEnv`: `gymnasium.Env`, one ego vehicle; the others rule-based, static or a policy.
- `DrivingParallelEnv`: PettingZoo `ParallelEnv` over one world.
- `SB3VecEnv`: stable-baselines3 `VecEnv`, one SB3 env per agent slot.

The adapters hold no simulation logic: they copy the native buffers into each library's
conventions. Modules import their RL library lazily (attribute access), so importing
`selfplaydrive.env` needs neither PettingZoo nor stable-baselines3. `registration` holds the
gymnasium ids (``selfplaydrive/SingleAgent-v0``, ``selfplaydrive/SelfPlay-v0``) that
``import selfplaydrive`` registers.
"""

from __future__ import annotations

import importlib
from typing import Any

_LAZY = {
    "GymVectorEnv": "selfplaydrive.env.gym_vector",
    "SingleAgentEnv": "selfplaydrive.env.gym_single",
    "DrivingParallelEnv": "selfplaydrive.env.pettingzoo_env",
    "SB3VecEnv": "selfplaydrive.env.sb3_vec_env",
}

__all__ = ["DrivingParallelEnv", "GymVectorEnv", "SB3VecEnv", "SingleAgentEnv"]


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'selfplaydrive.env' has no attribute {name!r}")
