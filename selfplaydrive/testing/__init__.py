"""Test helpers shipped with the library: component checkers (checkers.py), NumPy reference
kernels (reference.py, spawn_reference.py) and the comparison of two forms of a reward term
(terms.py). Importing this package is cheap: the checkers import the simulator when called."""

from selfplaydrive.testing.checkers import ComponentCheckError, check_reward_term, check_spawner

__all__ = ["ComponentCheckError", "check_reward_term", "check_spawner"]
