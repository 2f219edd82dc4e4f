"""The vectorized driving simulator (paper section 2): buffers, parameters, layout, env."""

from selfplaydrive.obs.layout import ObsLayout
from selfplaydrive.sim.actions import ContinuousActions, DiscreteActions
from selfplaydrive.sim.params import SimParams
from selfplaydrive.sim.vec_env import VecEnv

__all__ = ["ContinuousActions", "DiscreteActions", "ObsLayout", "SimParams", "VecEnv"]
