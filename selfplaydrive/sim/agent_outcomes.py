"""Per-agent end state of a finished world-episode (`VecEnv.record_agents`): what each agent
reached and where its next waypoint lay when the episode ended, read from the buffers before
the world is reset. `selfplaydrive.eval.misses` turns it into the reasons waypoints were
missed. Off by default; it runs once per finished world, never per step."""

from __future__ import annotations

from typing import Any

import numpy as np


def agent_outcomes(buffers: dict[str, np.ndarray], world: int, agents_per_world: int) -> dict[str, Any]:
    """End state of the valid agents of `world` (arrays of length n, the world's spawned agents).

    Args:
        buffers: `VecEnv.buffers` before the world's reset.
        world: World index.
        agents_per_world: Agent slots per world (A).

    Returns:
        {"ever": (n,) uint8 SD_EV_* bits over the episode, "reached": (n,) int waypoints reached,
        "assigned": (n,) int waypoints assigned, "ahead_m": (n,) float signed distance [m] of the
        pending waypoint along the car's heading (negative: the car is past it; NaN: none pending),
        "away_m": (n,) float straight-line distance [m] to it (NaN: none pending)}.
    """
    a = slice(world * agents_per_world, (world + 1) * agents_per_world)
    valid = np.flatnonzero(buffers["agent_valid"][a])
    slots = valid + world * agents_per_world
    reached = buffers["wp_idx"][slots].astype(np.int64)
    assigned = buffers["num_wp"][slots].astype(np.int64)
    pending = reached < assigned
    k = np.minimum(reached, np.maximum(assigned - 1, 0))
    wps = buffers["waypoints"].reshape(buffers["x"].shape[0], -1, 2)
    dx = wps[slots, k, 0].astype(np.float64) - buffers["x"][slots]
    dy = wps[slots, k, 1].astype(np.float64) - buffers["y"][slots]
    h = buffers["heading"][slots].astype(np.float64)
    ahead = np.where(pending, dx * np.cos(h) + dy * np.sin(h), np.nan)
    away = np.where(pending, np.hypot(dx, dy), np.nan)
    return {
        "ever": buffers["ever"][slots].copy(),
        "reached": reached,
        "assigned": assigned,
        "ahead_m": ahead,
        "away_m": away,
    }
