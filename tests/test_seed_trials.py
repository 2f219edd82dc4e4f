"""benchmarks/seed_trials.py: settings parsed or refused by name, the tables' figures from
hand-made run folders, and a real two-setting comparison of tiny runs that resumes."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from loadfile import ROOT, load_file

trials = load_file(
    ROOT / "benchmarks" / "seed_trials.py", "seed_trials", register=True
)  # a dataclass needs its module


def test_settings_parse_and_bad_ones_are_refused_by_name():
    assert trials.parse_setting("default:") == trials.Setting("default", ())
    got = trials.parse_setting("c4:reward.terms.center=4  trainer.ent_coef=0.01")
    assert got == trials.Setting("c4", ("reward.terms.center=4", "trainer.ent_coef=0.01"))
    for bad in ("reward.terms.center=4", "a b:x=1", ":x=1"):
        with pytest.raises(ValueError, match="expected NAME:OVERRIDES"):
            trials.parse_setting(bad)
    with pytest.raises(SystemExit):
        trials.main(["--out", "x", "--setting", "a:", "--setting", "a:y=1", "--table-only"])


def _fake_run(folder: Path, completion: float, collision: float, nested: bool = False) -> None:
    """Three updates of 1M slot-steps each, half the slots acting: 0.5M, 1.0M, 1.5M agent-steps."""
    folder.mkdir(parents=True)
    rows = [
        {"step": 1_000_000 * (i + 1), "charts/active_share": 0.5, "recent/waypoint_completion": 0.1 * (i + 1),
         "recent/collision_rate": 0.4, "recent/offroad_rate": 0.1}
        for i in range(3)
    ]  # fmt: skip
    (folder / "metrics.jsonl").write_text("\n".join(map(json.dumps, rows)) + "\n{half a li")
    ev = {"waypoint_completion": completion, "collision_rate": collision}
    (folder / "eval.json").write_text(json.dumps({"fixed_eval_coefficients": ev} if nested else ev))


def test_tables_hand_computed(tmp_path):
    base, other = trials.Setting("base"), trials.Setting("other", ("x=1",))
    _fake_run(tmp_path / "base_s0", 0.50, 0.30)
    _fake_run(tmp_path / "base_s1", 0.40, 0.20, nested=True)  # a conditioned run: the paper protocol's entry
    _fake_run(tmp_path / "other_s0", 0.60, 0.20)
    _fake_run(tmp_path / "other_s1", 0.60, 0.15)
    text = trials.tables(tmp_path, [base, other], [0, 1])
    # 1M agent-steps are passed at the second update; 2M never; the end is the third update
    assert "| base | 0 | 20.0 / 0.40 / 0.10 | - | - | - | 30.0 / 0.40 / 0.10 (1.50M) | 50.0 / 0.300 |" in text
    assert "| base | 1 |" in text and "| 40.0 / 0.200 |" in text
    # means 45.0 % / 0.250 and 60.0 % / 0.175; paired differences +10, +20 points (mean 15, se 5)
    # and -0.10, -0.05 (mean -0.075, se 0.025); seeds meeting both halves: other_s0 (0.20) and other_s1
    assert "| base | 2 | 45.0 | 0.250 | 0/2 | +0.0 +- 0.0 | +0.000 +- 0.000 |" in text
    assert "| other | 2 | 60.0 | 0.175 | 2/2 | +15.0 +- 5.0 | -0.075 +- 0.025 |" in text


def test_a_missing_run_shows_dashes_and_counts_no_seed(tmp_path):
    _fake_run(tmp_path / "a_s0", 0.5, 0.2)
    text = trials.tables(tmp_path, [trials.Setting("a")], [0, 1])
    assert "| a | 1 | - | - | - | - | - | - |" in text
    assert "| a | 1 | 50.0 | 0.200 | 1/1 |" in text


def test_tiny_comparison_trains_each_pair_once_and_resumes(tmp_path, capsys):
    pytest.importorskip("torch")
    tiny = (
        "env.num_worlds=1 spawner.num_agents=8 trainer.rollout_length=8 trainer.total_steps=128 "
        "trainer.eval_episodes=1 trainer.eval_max_steps=3000"
    )
    args = ["--out", str(tmp_path), "--seeds", "0", "--parallel", "2"]
    args += ["--setting", f"a:{tiny}", "--setting", f"b:{tiny} reward.terms.center=4"]
    assert trials.main(args) == 0
    first = capsys.readouterr()
    assert first.err.count("exit 0,") == 2
    for name in ("a_s0", "b_s0"):
        assert (tmp_path / name / "eval.json").is_file() and (tmp_path / f"{name}.log").is_file()
    resolved = (tmp_path / "b_s0" / "resolved_config.yaml").read_text()
    assert "center: 4" in resolved
    # each setting: its run's row with an evaluation, and a means row over that one seed
    assert first.out.count("| a | 0 |") == 1 and first.out.count("| b | 0 |") == 1
    assert "| a | 1 |" in first.out and "| b | 1 |" in first.out
    assert len(re.findall(r"^\| [ab] \| 0 \|.* \| \d+\.\d / \d\.\d{3} \|$", first.out, re.M)) == 2
    assert trials.main(args) == 0  # every pair has its eval.json: nothing trains again
    again = capsys.readouterr()
    assert "exit" not in again.err and again.out == first.out
