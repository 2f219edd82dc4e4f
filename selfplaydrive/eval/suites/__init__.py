"""Rule-adherence suites of paper section 5.3, generated on a map and classified automatically:
turning from the correct lane, yielding at stop lines (also with stop lines hidden from the
observation) and crosswalks (pedestrian waiting, pedestrian crossing); and the failure modes of
sections 5.1-5.2: red lights (waiting, running, bypassing through the oncoming lane), stop signs
(full / rolling / no stop, with and without cross traffic) and spawn sanity (agents starting in
or right in front of another body). docs/suites.md."""

from selfplaydrive.eval.suites.base import (
    FixedScenarioSpawner,
    Suite,
    SuiteScenario,
    Trajectory,
    hide_stop_lines,
    run_suite,
)
from selfplaydrive.eval.suites.crosswalks import CrosswalkSuite, classify_crosswalk
from selfplaydrive.eval.suites.red_lights import RedLightSuite, classify_red_light
from selfplaydrive.eval.suites.report import FAILURE_COUNTS, PAPER_COUNTS, default_suites, run_all_suites
from selfplaydrive.eval.suites.spawn_sanity import SpawnSanitySuite, classify_spawn
from selfplaydrive.eval.suites.stop_lines import StopLineSuite, classify_stop_line, compare_runs
from selfplaydrive.eval.suites.stop_signs import StopSignSuite, classify_stop_sign
from selfplaydrive.eval.suites.turn_lanes import TurnLaneSuite, classify_turn

__all__ = [
    "FAILURE_COUNTS",
    "PAPER_COUNTS",
    "CrosswalkSuite",
    "FixedScenarioSpawner",
    "RedLightSuite",
    "SpawnSanitySuite",
    "StopLineSuite",
    "StopSignSuite",
    "Suite",
    "SuiteScenario",
    "Trajectory",
    "TurnLaneSuite",
    "classify_crosswalk",
    "classify_red_light",
    "classify_spawn",
    "classify_stop_line",
    "classify_stop_sign",
    "classify_turn",
    "compare_runs",
    "default_suites",
    "hide_stop_lines",
    "run_all_suites",
    "run_suite",
]
