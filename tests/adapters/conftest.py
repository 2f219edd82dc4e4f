"""Fixtures of the adapter tests: a small junction grid with the paper's spawner, and the
hand-built scenarios of tests/sim/helpers.py (loaded by path: it is not a package)."""

from __future__ import annotations

import pytest
from loadfile import load_sim_helpers

from selfplaydrive.maps import compile_map
from selfplaydrive.scenario._testmaps import grid_elements
from selfplaydrive.scenario.spawner import PaperSpawner
from selfplaydrive.sim import VecEnv


@pytest.fixture(scope="session")
def sim_helpers():
    return load_sim_helpers()


@pytest.fixture(scope="session")
def grid_map():
    """4 x 4 junctions 60 m apart, one lane per direction, traffic lights, crosswalks."""
    return compile_map(grid_elements(nx=4, ny=4, block=60.0))


@pytest.fixture(scope="session")
def make_env(grid_map):
    """Factory of VecEnvs on the grid with a small paper spawner (8 agents, short episodes)."""

    def make(num_worlds: int = 1, num_agents: int = 8, episode_lengths=(4.0,), **kwargs) -> VecEnv:
        sp = PaperSpawner(
            num_agents=num_agents,
            num_static=4,
            num_pedestrians=2,
            min_region_lane_length=300.0,
            episode_lengths=episode_lengths,
        )
        return VecEnv(grid_map, sp, num_worlds, **kwargs)

    return make
