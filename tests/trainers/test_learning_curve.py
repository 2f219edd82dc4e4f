"""benchmarks/learning_curve.py: time to completion thresholds from a run's metrics.jsonl."""

from __future__ import annotations

import json

import pytest
from ppo_helpers import load_benchmark


@pytest.fixture(scope="module")
def curve():
    return load_benchmark("learning_curve")


def row(step: int, time: float, completion: float) -> dict[str, float]:
    return {
        "step": step,
        "time": time,
        "charts/slot_sps": 1000.0,
        "recent/waypoint_completion": completion,
        "recent/collision_rate": 0.3,
        "recent/offroad_rate": 0.1,
    }


def test_minutes_to_each_threshold_count_from_the_runs_start(curve, tmp_path):
    # the first update logged 1,000 slot-steps at 1,000 slot-steps/s: the run started at t = 99 s
    rows = [row(1000, 100.0, 0.1), row(2000, 159.0, 0.55), row(3000, 219.0, 0.62), row(4000, 279.0, 0.58)]
    path = tmp_path / "metrics.jsonl"
    lines = [json.dumps(r) for r in rows] + [json.dumps({"step": 5000, "time": 300.0}), '{"step": 6000, "ti']
    path.write_text("\n".join(lines), encoding="utf-8")  # a row without completion, a cut last line
    read = curve.read(path)
    assert [r["step"] for r in read] == [1000, 2000, 3000, 4000]
    out = curve.summary(read, [0.5, 0.6, 0.8], points=2)
    assert out[0] == "completion >= 50%: 1.00 min, 2,000 slot-steps"
    assert out[1] == "completion >= 60%: 2.00 min, 3,000 slot-steps"
    assert out[2] == "completion >= 80%: not reached"
    assert out[3] == "best: 62.0% at 2.00 min"
    assert len(out) == 4 + 1 + 2  # header and the first and last rows
    assert curve.summary([], [0.5]) == ["no update with a finished world-episode was logged"]


def test_a_resumed_run_counts_its_training_minutes_not_the_pause(curve):
    # the clock's 60 s between rows (within PAUSE_S of the rate's 1 s, so counted as they are), then
    # a day's pause before the resumed process logged step 4,000: counted as its own 1 s
    rows = [row(1000, 100.0, 0.1), row(2000, 160.0, 0.3), row(3000, 220.0, 0.4), row(4000, 86_620.0, 0.85)]
    assert curve.training_seconds(rows) == [1.0, 61.0, 121.0, 122.0]
    out = curve.summary(rows, [0.8], points=2)
    assert out[0] == "completion >= 80%: 2.03 min, 4,000 slot-steps"
    # a gap within PAUSE_S of the update's own time is the clock's (a slow update, not a pause)
    rows[3]["time"] = 220.0 + 1.0 + curve.PAUSE_S
    assert curve.training_seconds(rows)[3] == 121.0 + 1.0 + curve.PAUSE_S
