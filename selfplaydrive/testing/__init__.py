"""Test helpers shipped with the library: component checkers (checkers.py), NumPy reference
kernels (reference.py, spawn_reference.py) and the comparison of two forms of a reward term
(terms.py). Importing this package loads neither torch nor the simulator: the checkers build
their envs when called.

`check_physics` and `check_encoder` join these exports with the physics-model and
observation-encoder components (their own modules in this package).
"""

from selfplaydrive.testing.checkers import ComponentCheckError, check_reward_term, check_spawner

__all__ = ["ComponentCheckError", "check_reward_term", "check_spawner"]
