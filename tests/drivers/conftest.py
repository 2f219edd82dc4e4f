"""Maps for the driver tests."""

from __future__ import annotations

import pytest

from selfplaydrive.maps import compile_map
from selfplaydrive.scenario._testmaps import grid_elements


@pytest.fixture(scope="session")
def grid_map():
    """4 x 4 junctions 60 m apart, one lane per direction, traffic lights, crosswalks."""
    return compile_map(grid_elements(nx=4, ny=4, block=60.0))
