"""Vehicle dynamics models (paper section 2.6). Each selects a Cython kernel once, at
construction; the step never branches on a Python object."""

from selfplaydrive.physics.models import BicycleModel, FrictionBicycleModel
from selfplaydrive.physics.pymunk_model import PymunkModel

__all__ = ["BicycleModel", "FrictionBicycleModel", "PymunkModel"]
