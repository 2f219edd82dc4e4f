"""Each failure-mode suite of issue #15 runs alone from `selfplaydrive eval` (the rule-based
driver, a few scenarios) on the bundled town and on Tartu, and writes its table
(suites.json, suites.md; docs/suites.md)."""

from __future__ import annotations

import json

import pytest
from sharedmaps import shared_map

from selfplaydrive.cli import main

ALL = ("turn_lanes", "stop_lines", "crosswalks", "red_lights", "stop_signs", "spawn_sanity")
COUNTS = {"crosswalks": 2, "red_lights": 2, "stop_signs": 2, "spawn_sanity": 4}
# rows of the markdown table each suite must write
ROWS = {
    "crosswalks": ["crosswalks.summary.waiting.road_edge", "crosswalks.summary.crossing.road_edge"],
    "red_lights": ["red_lights.summary.stopped", "red_lights.summary.ran", "red_lights.summary.bypassed"],
    "stop_signs": ["stop_signs.summary.n"],
    "spawn_sanity": ["spawn_sanity.summary.overlap", "spawn_sanity.summary.close_ahead"],
}


def _eval_one(suite: str, map_args: list[str], out) -> tuple[dict, str]:
    drop = [f"~eval.suites.{s}" for s in ALL if s != suite]
    args = ["eval", "eval=quick", "eval.analyses=[suites]", *drop, f"eval.suites.{suite}={COUNTS[suite]}"]
    assert main([*args, "eval.batch_size=4", *map_args, f"hydra.run.dir={out}"]) == 0
    return json.loads((out / "suites.json").read_text()), (out / "suites.md").read_text()


def _check(suite: str, data: dict, table: str) -> None:
    assert set(data) == {suite}
    assert data[suite]["generated"] > 0
    for row in ROWS[suite]:
        assert f"| {row} |" in table, row
    summary = data[suite]["summary"]
    if suite == "crosswalks":  # road-edge terminations reported apart from `other`
        assert {"road_edge", "other"} <= set(summary["waiting"]) & set(summary["crossing"])
    if suite == "spawn_sanity":  # the default spawner starts nobody inside or right behind a body
        assert summary["overlap"]["numerator"] == 0 and summary["close_ahead"]["numerator"] == 0


@pytest.mark.parametrize("suite", sorted(COUNTS))
def test_suite_alone_on_bundled_town(suite, tmp_path):
    _check(suite, *_eval_one(suite, [], tmp_path / "run"))


@pytest.mark.parametrize("suite", sorted(COUNTS))
def test_suite_alone_on_tartu(suite, tmp_path, monkeypatch):
    path = shared_map("tartu_lanelet2/tartu_demo_l.osm")
    monkeypatch.setenv("SELFPLAYDRIVE_SHARED_MAPS", str(path.parents[1]))
    _check(suite, *_eval_one(suite, ["map=tartu"], tmp_path / "run"))


def test_suites_shorthand_runs_only_the_named_suites(tmp_path):
    """`selfplaydrive eval suites=[...]` (issue #15): only those suites, no long-form."""
    out = tmp_path / "run"
    args = ["eval", "eval=quick", "suites=[red_lights,spawn_sanity]", "eval.suites.red_lights=2"]
    assert main([*args, "eval.suites.spawn_sanity=4", "eval.batch_size=4", f"hydra.run.dir={out}"]) == 0
    assert set(json.loads((out / "suites.json").read_text())) == {"red_lights", "spawn_sanity"}
    assert not list(out.glob("longform*"))


def test_suites_shorthand_names_an_unknown_suite(tmp_path, capsys):
    assert main(["eval", "eval=quick", "suites=[red_light]", f"hydra.run.dir={tmp_path / 'run'}"]) != 0
    err = capsys.readouterr().err
    assert "suites: unknown ['red_light']" in err and "red_lights" in err
