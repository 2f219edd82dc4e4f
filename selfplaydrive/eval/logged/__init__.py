"""Logged scenarios, Waymax-style (paper section 5.2): a loader of the GPUDrive JSON layout and
the closed-loop evaluation of a policy on them (docs/analyses.md)."""

from selfplaydrive.eval.logged.gpudrive_json import LoggedScenario, load_gpudrive_json
from selfplaydrive.eval.logged.run import LogSpawner, build_scenario, evaluate_logged, run_logged

__all__ = [
    "LogSpawner",
    "LoggedScenario",
    "build_scenario",
    "evaluate_logged",
    "load_gpudrive_json",
    "run_logged",
]
