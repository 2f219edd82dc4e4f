"""`scenario.protocol.paper_protocol`: a built spawner draws the paper's evaluation worlds inside
the block (fixed coefficients, no curricula) and its own worlds again after it."""

from __future__ import annotations

import numpy as np
import pytest

from selfplaydrive.errors import ConfigError
from selfplaydrive.maps.loader import load_map
from selfplaydrive.scenario.conditioning import ConditioningSampler
from selfplaydrive.scenario.protocol import (
    follows_protocol,
    has_protocol,
    paper_protocol,
    uses_paper_coefficients,
)
from selfplaydrive.scenario.spawner import PaperSpawner

FIELDS = ("agent_xy", "agent_speed", "waypoints", "num_waypoints", "coeffs", "static_xy", "ped_path")


@pytest.fixture(scope="module")
def town():
    return load_map("default")


def _curriculum_spawner(**kwargs) -> PaperSpawner:
    return PaperSpawner(
        num_agents=16, turn_lane_starts=4, turn_lane_worlds=0.5, lane_change_prob=0.5, **kwargs
    )


def _same(a, b) -> None:
    for name in FIELDS:
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def test_inside_the_block_the_worlds_are_the_papers_evaluation_worlds(town):
    spawner = _curriculum_spawner()
    paper = PaperSpawner(num_agents=16, lane_change_prob=0.5, conditioning=ConditioningSampler(mode="eval"))
    assert not follows_protocol(spawner)
    with paper_protocol(spawner):
        assert uses_paper_coefficients(spawner) and follows_protocol(spawner)
        inside = spawner.sample(town, np.random.default_rng(4))
    _same(inside, paper.sample(town, np.random.default_rng(4)))
    n = int(inside.agent_valid.sum())
    expected = ConditioningSampler().eval_vector()
    np.testing.assert_array_equal(inside.coeffs[:n], np.tile(expected, (n, 1)))


def test_the_spawner_is_restored_after_the_block_and_after_an_error(town):
    spawner = _curriculum_spawner()
    before = spawner.sample(town, np.random.default_rng(8))
    with pytest.raises(RuntimeError, match="boom"):
        with paper_protocol(spawner):
            raise RuntimeError("boom")
    assert not uses_paper_coefficients(spawner) and not follows_protocol(spawner)
    settings = (spawner.conditioning.mode, spawner.turn_lane_starts, spawner.turn_lane_worlds)
    assert settings == ("train", 4, 0.5)
    _same(spawner.sample(town, np.random.default_rng(8)), before)


def test_curricula_switched_on_after_construction_are_built_when_first_used(town):
    spawner = PaperSpawner(num_agents=16, lane_change_prob=0.5)
    spawner.turn_lane_worlds = 1.0
    world = spawner.sample(town, np.random.default_rng(2))
    # a turn-lane world holds turn-lane starts only: two waypoints per agent
    valid = np.flatnonzero(world.agent_valid)
    assert len(valid) and set(world.num_waypoints[valid].tolist()) == {2}


def test_a_spawner_without_conditioning_is_named():
    class Bare:
        pass

    assert not has_protocol(Bare())
    with pytest.raises(ConfigError, match="Bare has no conditioning sampler"):
        with paper_protocol(Bare()):
            pass


def test_fixed_coefficients_with_a_curriculum_on_are_not_the_protocol():
    """`reward=eval` fixes the coefficients; a turn-lane curriculum beside it still trains on worlds
    the protocol has not (the trainer then evaluates a second time, inside `paper_protocol`)."""
    fixed = ConditioningSampler(mode="eval")
    assert follows_protocol(PaperSpawner(num_agents=16, conditioning=fixed))
    curriculum = PaperSpawner(num_agents=16, turn_lane_worlds=0.25, conditioning=fixed)
    assert uses_paper_coefficients(curriculum) and not follows_protocol(curriculum)
