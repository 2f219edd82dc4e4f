"""Vehicle dynamics models (paper section 2.6) as plug-in components (physics/components.py):
each model is a C function the step calls once per world through a pointer, chosen once, at
construction; the step never branches on a Python object."""

from selfplaydrive.physics.components import KernelPhysics, PhysicsModel, load_physics
from selfplaydrive.physics.models import BicycleModel, DeltaModel, FrictionBicycleModel, JerkBicycleModel
from selfplaydrive.physics.pymunk_model import PymunkModel

__all__ = [
    "BicycleModel",
    "DeltaModel",
    "FrictionBicycleModel",
    "JerkBicycleModel",
    "KernelPhysics",
    "PhysicsModel",
    "PymunkModel",
    "load_physics",
]
