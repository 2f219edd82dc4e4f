"""Observation encoders (paper section 2.5) and the layout models read (`ObsLayout`).

`PaperEncoder` is the paper's encoder, `PartialObsEncoder` adds occlusion and perception noise,
`RulesEncoder` adds STOP/YIELD line types and crosswalk occupancy (constants: `rule_features`),
`KernelEncoder` wraps a compiled encoder (numba, Cython, C) and any object with ``name``,
``layout``, ``radius`` and ``__call__(state)`` is a Python encoder (docs/components.md "Write an
observation encoder"). `ObsHook` appends columns in Python.
"""

from selfplaydrive.obs.config import ObsConfig, ObsHook
from selfplaydrive.obs.encoders import (
    Encoder,
    KernelEncoder,
    PaperEncoder,
    PartialObsEncoder,
    PythonEncoder,
    as_encoder,
    bind_encoder,
)
from selfplaydrive.obs.layout import EGO_FEATURES, OBJECT_FEATURES, ROAD_FEATURES, ObsLayout
from selfplaydrive.obs.loading import load_encoder
from selfplaydrive.obs.rules import RulesEncoder

__all__ = [
    "EGO_FEATURES",
    "OBJECT_FEATURES",
    "ROAD_FEATURES",
    "Encoder",
    "KernelEncoder",
    "ObsConfig",
    "ObsHook",
    "ObsLayout",
    "PaperEncoder",
    "PartialObsEncoder",
    "PythonEncoder",
    "RulesEncoder",
    "as_encoder",
    "bind_encoder",
    "load_encoder",
]
