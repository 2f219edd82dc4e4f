"""Shared fixtures: paths to ../shared/maps (skip with a reason when absent) and tiny maps."""

from __future__ import annotations

import numpy as np
import pytest
from sharedmaps import SHARED_MAPS, shared_map  # noqa: F401  (re-exported for fixtures)

from selfplaydrive.maps import LaneElement, MapElements, PolylineElement, compile_map


@pytest.fixture
def straight_map():
    """Two parallel 200 m lanes along +x (right-hand traffic), road edges 3.5 m outside."""
    y0, w = 0.0, 3.5
    lanes = [
        LaneElement(np.array([[0.0, y0], [200.0, y0]]), width=w, speed_limit=13.9, source_id="east"),
        LaneElement(np.array([[200.0, y0 + w], [0.0, y0 + w]]), width=w, speed_limit=13.9, source_id="west"),
    ]
    edges = [
        PolylineElement(np.array([[0.0, y0 - w / 2], [200.0, y0 - w / 2]]), source_id="south"),
        PolylineElement(np.array([[0.0, y0 + 1.5 * w], [200.0, y0 + 1.5 * w]]), source_id="north"),
    ]
    return compile_map(MapElements(name="straight", lanes=lanes, road_edges=edges))
