"""How often the object block of the observation is full: bodies within the observation radius
against the `obs.max_objects` slots that hold the nearest of them (paper section 2.5: the
nearest 63 within 100 m; the main job keeps 16).

The env is built with a wide object block (`--wide`, default 63 slots) so that every body
within the radius is counted, and driven for `--steps` steps with the "keep speed and heading"
action (the middle choice of every action dimension; the scene's density, not the driving, is
measured). For each acting agent's observation it counts the valid object rows, and reports per
agents-per-world setting the mean count, and for each slot count K of `--slots` the share of
observations with at least K bodies (the K slots all taken, so farther bodies are not seen)
and the mean number of bodies beyond the K nearest.

    python benchmarks/obs_saturation.py                                # the main job, 16 and 32 agents
    python benchmarks/obs_saturation.py map=tartu --agents 32 --slots 16 32 63   # overrides first
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence

import numpy as np
from reward_landscape import KeepSpeedDriver  # a sibling script: benchmarks/ is on sys.path

from selfplaydrive.builder import build_env, compose


def valid_counts(env, steps: int, seed: int) -> np.ndarray:
    """Valid object rows of every acting agent's observation over `steps` keep-speed steps
    after `env.reset(seed)`; (M,) int64, one entry per (step, acting agent)."""
    col = env.layout.feature_index("object", "valid")
    actions = KeepSpeedDriver(env).act()
    env.reset(seed=seed)
    counts = []
    for _ in range(steps):
        objects = env.layout.split(env.observations[env.masks])["objects"]
        counts.append(np.count_nonzero(objects[:, :, col] > 0.5, axis=1))
        env.step(actions)
    return np.concatenate(counts).astype(np.int64)


def summarize(counts: np.ndarray, slots: Sequence[int], wide: int) -> dict[str, object]:
    """Mean count; per K in `slots` the share of counts >= K and the mean of max(count - K, 0).

    Args:
        counts: (M,) valid object rows per observation, from an env with `wide` slots.
        slots: Slot counts K to report.
        wide: The slots the counts were taken with; `share_at_wide` > 0 means that even they
            were full, so the counts are lower bounds.
    """
    if counts.size == 0:
        raise ValueError("counts: no acting agent was observed (steps or agents too few)")
    out: dict[str, object] = {
        "observations": int(counts.size),
        "mean_bodies": float(counts.mean()),
        "share_at_wide": float(np.mean(counts >= wide)),
    }
    for k in slots:
        out[f"share_full_{k}"] = float(np.mean(counts >= k))
        out[f"mean_beyond_{k}"] = float(np.maximum(counts - k, 0).mean())
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("overrides", nargs="*", help="Hydra overrides of the train config")
    parser.add_argument("--agents", type=int, nargs="+", default=[16, 32], help="agents per world")
    parser.add_argument(
        "--slots", type=int, nargs="+", default=None, help="K (default: the config's max_objects)"
    )
    parser.add_argument("--wide", type=int, default=63, help="object slots to count with")
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    rows = []
    for agents in args.agents:
        cfg = compose("train", [*args.overrides, f"spawner.num_agents={agents}"])
        slots = args.slots or [int(cfg.obs.max_objects)]
        if any(k > args.wide for k in slots):
            parser.error(f"--slots {slots}: each K must be at most --wide {args.wide}")
        cfg.obs.max_objects = args.wide
        env = build_env(cfg)
        rows.append(
            {"agents": agents, **summarize(valid_counts(env, args.steps, args.seed), slots, args.wide)}
        )
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    for row in rows:
        parts = [f"{k} {v:.3f}" if isinstance(v, float) else f"{k} {v}" for k, v in row.items()]
        print(", ".join(parts))
    return 0


if __name__ == "__main__":
    sys.exit(main())
