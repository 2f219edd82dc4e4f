"""`selfplaydrive eval` with the rule-based driver runs every suite and the long-form evaluation
on the bundled map and writes JSON plus markdown tables into the run folder."""

from __future__ import annotations

import json

import pytest

from selfplaydrive.cli import main


def test_eval_rule_based_writes_reports(tmp_path, capsys):
    out = tmp_path / "run"
    code = main(
        [
            "eval",
            "eval=quick",
            "eval.suites.turn_lanes=2",
            "eval.suites.stop_lines=2",
            "eval.suites.crosswalks=2",
            "eval.longform.duration_s=10",
            "eval.longform.num_worlds=1",
            f"hydra.run.dir={out}",
        ]
    )
    assert code == 0
    for name in ("suites", "longform"):
        data = json.loads((out / f"{name}.json").read_text())
        assert data, f"{name}.json is empty"
        assert (out / f"{name}.md").read_text().startswith("## ")
    suites = json.loads((out / "suites.json").read_text())
    assert set(suites) == {"turn_lanes", "stop_lines", "crosswalks"}
    assert suites["stop_lines"]["generated"] == 2
    longform = json.loads((out / "longform.json").read_text())
    assert longform["km"] > 0
    meta = json.loads((out / "run_meta.json").read_text())
    assert meta["seed"] == 0
    assert len(meta["git_commit"]) == 40 or meta["git_commit"] == "unknown"


def test_eval_unknown_analysis_is_a_config_error(tmp_path):
    from selfplaydrive.builder import compose
    from selfplaydrive.errors import ConfigError
    from selfplaydrive.eval.app import run_eval

    cfg = compose("eval", ["eval=quick", "eval.analyses=[suites,carla]"])
    with pytest.raises(ConfigError, match=r"carla.*valid choices: suites, longform"):
        run_eval(cfg, tmp_path)
