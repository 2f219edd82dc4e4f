"""Maps for the spawner tests: synthetic grids (fast, no files) and a tiny straight road."""

from __future__ import annotations

import numpy as np
import pytest

from selfplaydrive.maps import LaneElement, MapElements, PolylineElement, compile_map
from selfplaydrive.scenario._testmaps import grid_elements


@pytest.fixture(scope="session")
def grid_map():
    """4 x 4 junctions 60 m apart, one lane per direction, lights, crosswalks, border stubs."""
    return compile_map(grid_elements(nx=4, ny=4, block=60.0))


@pytest.fixture(scope="session")
def grid2_map():
    """3 x 3 junctions 80 m apart with two lanes per direction (legal lane changes)."""
    return compile_map(grid_elements(nx=3, ny=3, block=80.0, lanes_per_dir=2, name="grid2"))


@pytest.fixture(scope="session")
def tiny_map():
    """One 40 m two-way road: room for two agents 15 m apart per direction at most."""
    w = 3.5
    lanes = [
        LaneElement(np.array([[0.0, 0.0], [40.0, 0.0]]), w, 13.9, source_id="east"),
        LaneElement(np.array([[40.0, w], [0.0, w]]), w, 13.9, source_id="west"),
    ]
    edges = [
        PolylineElement(np.array([[0.0, -w / 2], [40.0, -w / 2]]), source_id="south"),
        PolylineElement(np.array([[0.0, 1.5 * w], [40.0, 1.5 * w]]), source_id="north"),
    ]
    return compile_map(MapElements(name="tiny", lanes=lanes, road_edges=edges))
