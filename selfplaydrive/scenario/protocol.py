"""The paper's evaluation protocol on a live spawner (paper section 5).

Evaluations in the paper fix every reward coefficient at its evaluation value (every penalty
at its maximum, B = 0, D = 3 m) instead of drawing them per agent, and the worlds are the
paper's, so training curricula (`scenario.spawner.CURRICULUM_OPTIONS`) are off. A config can ask
for that up front (`reward=eval`, `without_curricula`); `paper_protocol` switches an already
built spawner for the span of a `with` block, so that a trainer can score its policy under
both the training distribution and the paper's protocol on the same env.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from selfplaydrive.errors import ConfigError
from selfplaydrive.scenario.spawner import CURRICULUM_OPTIONS


@contextmanager
def paper_protocol(spawner: object) -> Iterator[None]:
    """Within the block, `spawner` draws the fixed evaluation coefficients and no curricula.

    Only worlds sampled inside the block follow the protocol: reset the env after entering.
    The spawner's settings are restored on leaving, also after an exception.

    Args:
        spawner: A spawner with a `conditioning` sampler (`PaperSpawner` and its subclasses).

    Raises:
        ConfigError: The spawner has no conditioning sampler with a `mode`.
    """
    if not has_protocol(spawner):
        raise ConfigError(
            f"paper_protocol: the spawner {type(spawner).__name__} has no conditioning sampler with "
            "a mode, expected one like PaperSpawner's (scenario.conditioning.ConditioningSampler)"
        )
    conditioning = spawner.conditioning
    saved_mode = conditioning.mode
    saved = {key: getattr(spawner, key) for key in CURRICULUM_OPTIONS if hasattr(spawner, key)}
    conditioning.mode = "eval"
    for key in saved:
        setattr(spawner, key, CURRICULUM_OPTIONS[key])
    try:
        yield
    finally:
        conditioning.mode = saved_mode
        for key, value in saved.items():
            setattr(spawner, key, value)


def uses_paper_coefficients(spawner: object) -> bool:
    """Whether `spawner` already draws the fixed evaluation coefficients (`reward=eval`)."""
    return getattr(getattr(spawner, "conditioning", None), "mode", None) == "eval"


def follows_protocol(spawner: object) -> bool:
    """Whether `spawner` already draws the paper's evaluation worlds: the fixed evaluation
    coefficients (`reward=eval`, the main job's default) and every training curriculum off."""
    curricula_off = all(getattr(spawner, key, off) == off for key, off in CURRICULUM_OPTIONS.items())
    return uses_paper_coefficients(spawner) and curricula_off


def has_protocol(spawner: object) -> bool:
    """Whether `paper_protocol` can switch `spawner` (it has a conditioning sampler with a mode)."""
    return hasattr(getattr(spawner, "conditioning", None), "mode")
