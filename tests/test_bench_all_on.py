"""benchmarks/bench_all_on.py: the variants switch on what they claim, and a tiny run reports
every variant against the paper configuration (docs/benchmarks.md "Every new component on")."""

from __future__ import annotations

from pathlib import Path

import pytest
from loadfile import load_file

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_all_on.py"


@pytest.fixture(scope="module")
def bench():
    return load_file(SCRIPT, "bench_all_on")


def test_variants_switch_on_every_component(bench):
    envs = {k: bench.Runner(v, worlds=1, steps=2, seed=0).env for k, v in bench.VARIANTS.items()}
    assert type(envs["paper"].encoder).__name__ == "PaperEncoder"
    assert not set(bench.RULE_TERMS) & set(envs["paper"].term_names)
    assert type(envs["all_on_rules"].encoder).__name__ == "RulesEncoder"
    partial = envs["all_on_partial"].encoder
    assert type(partial).__name__ == "PartialObsEncoder"
    assert partial.params["occlusion"] == 1 and partial.params["p_miss"] == pytest.approx(0.05)
    for k in ("all_on_rules", "all_on_partial"):
        assert set(bench.RULE_TERMS) <= set(envs[k].term_names)
        assert list(envs[k].action_space.nvec) == [7, 9]  # the jerk model's (delta accel, delta steer)


def test_tiny_run_reports_every_variant(bench):
    result = bench.measure(worlds=1, steps=3, warmup=1, rounds=2, seed=0)
    assert list(result) == list(bench.VARIANTS)
    assert result["paper"]["throughput_vs_paper"] == 1.0
    for v in result.values():
        assert v["agent_steps_per_cpu_s"] > 0 and v["ns_per_agent_step_cpu"] > 0
    text = bench.table(result)
    assert text.count("\n") == 1 + len(bench.VARIANTS) and "| all_on_partial |" in text
