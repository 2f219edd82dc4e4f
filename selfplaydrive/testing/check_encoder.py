"""`check_encoder`: validate an observation encoder against its contract (docs/components.md
"Write an observation encoder"; selfplaydrive_abi.h `sd_encoder_fn`).

Checks, over a short rollout with random actions:

1. shape: the observations are (N, layout.obs_dim) and the layout's blocks add up to obs_dim;
2. values: every row the env hands out (active slots, final observations of the agents that
   ended) is finite and within [-layout.bound, layout.bound];
3. determinism: the same seed gives the same buffers, bit for bit, at 1 and 2 threads;
4. no writes outside the observation (compiled encoders): around an extra call of the encoder
   alone (`World.encode`), every buffer other than `obs` and the scratch the contract allows
   (`cand`, `cand_d`, `obj_rows`, `road_rows`) is unchanged, and so are the `obs` rows of the
   inactive slots.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import Any

import numpy as np

# buffers an encoder may write besides its rows (selfplaydrive_abi.h `sd_encoder_fn`)
SCRATCH = ("cand", "cand_d", "obj_rows", "road_rows")


class EncoderCheckError(AssertionError):
    """An encoder broke its contract; the message names the check, the step and the slot."""


@dataclass(frozen=True)
class EncoderReport:
    """What `check_encoder` saw.

    Attributes:
        name: The encoder's name.
        obs_dim: Columns per row.
        steps: Steps rolled out (at each of 1 and 2 threads).
        rows_checked: Observation rows checked for finite, bounded values.
        max_abs: Largest |value| seen in those rows.
        isolation_checks: Calls of the encoder alone around which the other buffers were compared.
    """

    name: str
    obs_dim: int
    steps: int
    rows_checked: int
    max_abs: float
    isolation_checks: int


def check_encoder(
    encoder: Any,
    road_map: Any = None,
    *,
    spawner: Any = None,
    num_worlds: int = 4,
    steps: int = 40,
    seed: int = 0,
    **env_kwargs: Any,
) -> EncoderReport:
    """Validate `encoder` (anything `VecEnv(obs=...)` takes) by rolling out two envs.

    Args:
        encoder: The encoder under test.
        road_map: The map (default: the bundled town).
        spawner: The spawner (default: a small `PaperSpawner`: 8 agents, 8 static, 2 pedestrians,
            4 s episodes, so that resets happen within the rollout).
        num_worlds: Worlds per env.
        steps: Steps of the rollout.
        seed: Seed of the envs and of the random actions.
        **env_kwargs: Further `VecEnv` arguments.

    Returns:
        An `EncoderReport`.

    Raises:
        EncoderCheckError: The first broken rule, naming the check, step and slot.
    """
    from selfplaydrive.maps.loader import load_map
    from selfplaydrive.obs.encoders import KernelEncoder, as_encoder
    from selfplaydrive.scenario.spawner import PaperSpawner
    from selfplaydrive.sim.vec_env import VecEnv

    enc = as_encoder(encoder)
    if road_map is None:
        road_map = load_map("default")
    if spawner is None:
        spawner = PaperSpawner(num_agents=8, num_static=8, num_pedestrians=2, episode_lengths=(4.0,))
    envs = [
        VecEnv(road_map, spawner, num_worlds, obs=enc, seed=seed, num_threads=t, **env_kwargs) for t in (1, 2)
    ]
    lay = envs[0].layout
    name = enc.name
    n = envs[0].num_agents
    blocks = sum(int(np.prod(shape)) for shape in lay.blocks().values())
    if blocks != lay.obs_dim or enc.layout.obs_dim > lay.obs_dim:
        raise EncoderCheckError(
            f"encoder {name!r}: layout blocks {lay.blocks()} add up to {blocks}, obs_dim {lay.obs_dim}"
        )
    for env in envs:
        if env.observations.shape != (n, lay.obs_dim):
            raise EncoderCheckError(
                f"encoder {name!r} (shape): observations {env.observations.shape}, "
                f"expected ({n}, {lay.obs_dim})"
            )
    acts = _random_actions(envs[0].action_space, steps, n, seed)
    obs0 = [env.reset(seed) for env in envs]
    _same(envs, name, -1)
    rows = 0
    max_abs = 0.0
    d = enc.layout.obs_dim
    rows, max_abs = _values(
        obs0[0][envs[0].masks][:, :d], name, lay.bound, -1, np.flatnonzero(envs[0].masks), rows, max_abs
    )
    isolation = 0
    for k in range(steps):
        for env in envs:
            env.step(acts[k])
        _same(envs, name, k)
        env = envs[0]
        ended = env.terminations | env.truncations
        rows, max_abs = _values(
            env.observations[env.masks][:, :d], name, lay.bound, k, np.flatnonzero(env.masks), rows, max_abs
        )
        rows, max_abs = _values(
            env.final_observations[ended][:, :d], name, lay.bound, k, np.flatnonzero(ended), rows, max_abs
        )
        if isinstance(enc, KernelEncoder) and k % 5 == 4:
            _isolated(env, name, k)
            isolation += 1
    return EncoderReport(name, lay.obs_dim, steps, rows, max_abs, isolation)


def _random_actions(space: Any, steps: int, n: int, seed: int) -> np.ndarray:
    """(steps, n, 2) uniform random actions of a MultiDiscrete or Box action space."""
    rng = np.random.default_rng(seed)
    if hasattr(space, "nvec"):
        nvec = np.asarray(space.nvec)
        return rng.integers(0, nvec, size=(steps, n, len(nvec)))
    low, high = np.asarray(space.low), np.asarray(space.high)
    return rng.uniform(low, high, size=(steps, n, *low.shape)).astype(np.float32)


def _values(
    block: np.ndarray, name: str, bound: float, step: int, slots: np.ndarray, rows: int, max_abs: float
) -> tuple[int, float]:
    if block.size:
        bad = ~np.isfinite(block).all(axis=1)
        if bad.any():
            r = int(np.flatnonzero(bad)[0])
            raise EncoderCheckError(
                f"encoder {name!r} (finite): non-finite value at step {step}, agent slot {int(slots[r])}, "
                f"column {int(np.flatnonzero(~np.isfinite(block[r]))[0])}"
            )
        big = np.abs(block) > bound
        if big.any():
            r, c = (int(v) for v in np.argwhere(big)[0])
            raise EncoderCheckError(
                f"encoder {name!r} (bound): value {block[r, c]} at step {step}, agent slot {int(slots[r])}, "
                f"column {c} exceeds the declared bound {bound} (layout.bound)"
            )
        max_abs = max(max_abs, float(np.abs(block).max()))
    return rows + len(block), max_abs


def _digest(env: Any) -> dict[str, str]:
    return {k: hashlib.sha256(np.ascontiguousarray(v).tobytes()).hexdigest() for k, v in env.buffers.items()}


def _same(envs: list[Any], name: str, step: int) -> None:
    """Bit-identical buffers at 1 and 2 threads (scratch excluded: its content is undefined)."""
    a, b = (_digest(e) for e in envs)
    for key in a:
        if key not in SCRATCH and a[key] != b[key]:
            raise EncoderCheckError(
                f"encoder {name!r} (determinism): buffer {key!r} differs between 1 and 2 threads "
                f"after step {step}"
            )


def _isolated(env: Any, name: str, step: int) -> None:
    """Call the encoder alone and compare every other buffer before and after."""
    before = {k: v.copy() for k, v in env.buffers.items()}
    env._world.encode(1)
    inactive = ~before["active"].astype(bool)
    for key, old in before.items():
        new = env.buffers[key]
        if key in SCRATCH:
            continue
        if key == "obs":
            changed = (old[inactive] != new[inactive]).any(axis=1) & ~(
                np.isnan(old[inactive]) & np.isnan(new[inactive])
            ).all(axis=1)
            if changed.any():
                slot = int(np.flatnonzero(inactive)[np.flatnonzero(changed)[0]])
                raise EncoderCheckError(
                    f"encoder {name!r} (isolation): wrote the obs row of inactive agent slot {slot} "
                    f"(step {step})"
                )
            continue
        if not np.array_equal(old, new, equal_nan=old.dtype.kind == "f"):
            idx = np.argwhere(old != new)
            raise EncoderCheckError(
                f"encoder {name!r} (isolation): wrote buffer {key!r} at index "
                f"{tuple(int(i) for i in idx[0])} (step {step}); an encoder may write only its obs rows "
                f"and the scratch {SCRATCH}"
            )
