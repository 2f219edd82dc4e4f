"""Scenarios: spawners and the samplers they compose (paper sections 2.2, 2.3, 2.6).

`PaperSpawner` builds one world's initial `Scenario` from a `RoadMap` and a seeded generator;
see docs/scenario.md.
"""

from selfplaydrive.scenario.base import Spawner
from selfplaydrive.scenario.conditioning import ConditioningSampler, HiddenParamSampler
from selfplaydrive.scenario.index import MapIndex, map_index
from selfplaydrive.scenario.lights import LightSampler
from selfplaydrive.scenario.pedestrians import PedestrianSampler
from selfplaydrive.scenario.spawner import PaperSpawner
from selfplaydrive.scenario.types import COEFF_NAMES, HIDDEN_PARAMS, Scenario
from selfplaydrive.scenario.vehicles import VehicleSizeSampler

__all__ = [
    "COEFF_NAMES",
    "HIDDEN_PARAMS",
    "ConditioningSampler",
    "HiddenParamSampler",
    "LightSampler",
    "MapIndex",
    "PaperSpawner",
    "PedestrianSampler",
    "Scenario",
    "Spawner",
    "VehicleSizeSampler",
    "map_index",
]
