"""Rule-adherence suites of paper section 5.3, generated on a map and classified automatically:
turning from the correct lane, yielding at stop lines (also with stop lines hidden from the
observation) and crosswalks (pedestrian waiting, pedestrian crossing). docs/suites.md."""

from selfplaydrive.eval.suites.base import (
    FixedScenarioSpawner,
    Suite,
    SuiteScenario,
    Trajectory,
    hide_stop_lines,
    run_suite,
)
from selfplaydrive.eval.suites.crosswalks import CrosswalkSuite, classify_crosswalk
from selfplaydrive.eval.suites.report import PAPER_COUNTS, default_suites, run_all_suites
from selfplaydrive.eval.suites.stop_lines import StopLineSuite, classify_stop_line, compare_runs
from selfplaydrive.eval.suites.turn_lanes import TurnLaneSuite, classify_turn

__all__ = [
    "PAPER_COUNTS",
    "CrosswalkSuite",
    "FixedScenarioSpawner",
    "StopLineSuite",
    "Suite",
    "SuiteScenario",
    "Trajectory",
    "TurnLaneSuite",
    "classify_crosswalk",
    "classify_stop_line",
    "classify_turn",
    "compare_runs",
    "default_suites",
    "hide_stop_lines",
    "run_all_suites",
    "run_suite",
]
