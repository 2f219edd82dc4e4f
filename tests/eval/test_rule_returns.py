"""Does the reward pay for breaking a rule? `selfplaydrive.eval.rule_returns` and
`benchmarks/reward_landscape.py --rules` (issue #15 item 3, paper sections 5.1 and 5.3).

Under the main job's reward (the paper's terms, reshaped for a laptop) the oncoming-lane bypass
of a red light, rolling through a stop sign and not stopping at it earn more than obeying; the
fix_* experiments add the terms that make every rule breaker earn less. The tests that need the
new terms skip while the library lacks them."""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from sharedmaps import shared_map

from selfplaydrive.builder import build_env, compose
from selfplaydrive.eval import rule_returns as rr
from selfplaydrive.maps.loader import load_map
from selfplaydrive.maps.roadmap import StopKind
from selfplaydrive.rewards.components import registered_terms

REPO = Path(__file__).resolve().parents[2]
FIXES = {
    "fix_red_light": ["red_intersection"],
    "fix_stop_sign": ["stop_sign"],
    "fix_crosswalk_yield": ["crosswalk_yield"],
    "fix_wrong_way": ["wrong_way"],
    "fix_all": ["red_intersection", "stop_sign", "crosswalk_yield", "wrong_way"],
}
# the fixes whose terms depend on state the paper observation lacks (STOP/YIELD, crosswalk state)
OBSERVES_RULES = {"fix_stop_sign", "fix_crosswalk_yield", "fix_all"}


def _need_terms(names) -> None:
    missing = sorted(set(names) - set(registered_terms()))
    if missing:
        pytest.skip(f"reward term(s) {missing} not registered in this checkout (issue #15 item 1)")


@pytest.fixture(scope="module")
def town():
    return load_map("default")


@pytest.fixture(scope="module")
def main_job(town):
    """The loopholes under the main job's reward (experiment=laptop), 3 scenarios each."""
    return rr.compare(compose("train", []), count=3, maps=[town])


def _by_driver(results, loophole):
    return {r.driver: r for r in results if r.loophole == loophole}


# -- building blocks -----------------------------------------------------------------------
def test_swerve_path_hand_computed():
    path = np.array([[0.0, 0.0], [100.0, 0.0]])
    out = rr.swerve_path(path, 3.0, (10.0, 20.0), (30.0, 40.0))
    y = dict(zip(np.round(out[:, 0], 6), out[:, 1], strict=True))
    assert y[5.0] == pytest.approx(0.0)
    assert y[15.0] == pytest.approx(1.5)  # half-way up the cosine ramp
    assert y[25.0] == pytest.approx(3.0)
    assert y[35.0] == pytest.approx(1.5)  # half-way back
    assert y[45.0] == pytest.approx(0.0)
    assert np.allclose(out[:, 0], np.arange(0.0, 100.5, 0.5))


def test_with_stop_signs_relabels_only_maps_without_stop_lines(town):
    assert rr.with_stop_signs(town) is town  # the bundled town has STOP lines of its own
    all_yield = dataclasses.replace(town, stop_kind=np.full_like(town.stop_kind, StopKind.YIELD))
    relabelled = rr.with_stop_signs(all_yield)
    assert np.all(relabelled.stop_kind == StopKind.STOP)
    assert len(relabelled.stop_kind) == len(town.stop_kind)
    assert np.all(all_yield.stop_kind == StopKind.YIELD)  # the original is untouched
    assert rr.with_stop_signs(relabelled) is relabelled


def test_closed_hand_computed():
    def row(loophole, driver, compliant, returns):
        return rr.DriverResult(loophole, driver, compliant, np.array(returns), {}, [])

    results = [
        row("a", "good", True, [1.0, 3.0]),  # mean 2
        row("a", "bad", False, [1.0, 2.9]),  # mean 1.95 < 2: closed
        row("b", "good", True, [1.0]),
        row("b", "bad1", False, [0.0]),
        row("b", "bad2", False, [1.0]),  # equal: a tie still pays, open
        row("c", "good", True, []),  # no scenarios: not shown closed
        row("c", "bad", False, []),
    ]
    assert rr.closed(results) == {"a": True, "b": False, "c": False}


def test_bad_arguments_raise(town):
    cfg = compose("train", [])
    with pytest.raises(ValueError, match=r"names: unknown loophole\(s\) \['red'\]"):
        rr.compare(cfg, ["red"], maps=[town])
    with pytest.raises(ValueError, match="count: expected an integer >= 1, got 0"):
        rr.compare(cfg, count=0, maps=[town])


def test_batches_do_not_change_the_returns(town, main_job):
    """Each world's first episode is summed alone: 3 scenarios in batches of 2 (the second batch
    has a surplus world replaying the first scenario) give the returns of one batch of 3."""
    cfg = compose("train", [])
    split = rr.compare(cfg, ["red_intersection"], count=3, batch_size=2, maps=[town])
    whole = [r for r in main_job if r.loophole == "red_intersection"]
    for a, b in zip(split, whole, strict=True):
        assert a.driver == b.driver and a.outcomes == b.outcomes
        np.testing.assert_allclose(a.returns, b.returns, rtol=0, atol=1e-9)


# -- the main job: the hacks pay -------------------------------------------------------------
def test_returns_are_the_sum_of_the_term_columns(main_job):
    for r in main_job:
        assert len(r.returns) == 3 == len(r.outcomes)
        total = sum(r.terms.values())
        np.testing.assert_allclose(r.returns, total, atol=1e-4)


def test_main_job_red_light_hack_pays(main_job):
    d = _by_driver(main_job, "red_intersection")
    assert d["comply"].outcomes == ["stopped"] * 3
    assert d["bypass"].outcomes == ["bypassed"] * 3
    assert d["run"].outcomes == ["ran"] * 3
    # the paper's red-light term sees the car that runs the light, not the bypass
    assert np.all(d["comply"].terms["red_light"] == 0) and np.all(d["bypass"].terms["red_light"] == 0)
    assert np.all(d["run"].terms["red_light"] < 0)
    # the bypass rejoins its lane and reaches both waypoints: 2 x waypoint_reward 1.0 of the main job
    np.testing.assert_array_equal(d["bypass"].terms["waypoint"], 2.0)
    np.testing.assert_array_equal(d["comply"].terms["waypoint"], 0.0)
    assert d["bypass"].return_mean >= d["comply"].return_mean  # the hack pays
    assert not rr.closed(main_job)["red_intersection"]
    assert not rr.closed(main_job)["wrong_way"]


def test_main_job_stop_sign_hack_pays(main_job):
    d = _by_driver(main_job, "stop_sign")
    assert d["full_stop"].outcomes == ["full_stop"] * 3
    assert d["rolling_stop"].outcomes == ["rolling_stop"] * 3
    assert d["no_stop"].outcomes == ["no_stop"] * 3
    assert d["rolling_stop"].return_mean >= d["full_stop"].return_mean
    assert d["no_stop"].return_mean >= d["full_stop"].return_mean


def test_paper_settings_hacks_pay_by_a_small_margin(town):
    """`~experiment`: the paper's velocity (2.5e-4) and waypoint (0.25) rewards; the bypass and
    the rolling stop still earn at least as much as obeying (docs/analyses.md section 4)."""
    results = rr.compare(
        compose("train", ["~experiment"]), ["red_intersection", "stop_sign"], count=3, maps=[town]
    )
    red, stop = _by_driver(results, "red_intersection"), _by_driver(results, "stop_sign")
    assert np.all(red["bypass"].terms["red_light"] == 0)
    np.testing.assert_allclose(red["bypass"].terms["waypoint"], 0.5)  # 2 x 0.25
    assert red["bypass"].return_mean >= red["comply"].return_mean
    assert stop["rolling_stop"].return_mean >= stop["full_stop"].return_mean


def test_main_job_crosswalk_no_yield_hits_the_pedestrian(main_job):
    d = _by_driver(main_job, "crosswalk_yield")
    assert d["yield"].outcomes == ["stopped"] * 3
    # at constant speed the ego reaches the crossing with the pedestrian (the suite's timing):
    # the collision term already makes not yielding cost
    assert d["no_yield"].outcomes == ["collision"] * 3
    assert np.all(d["no_yield"].terms["collision"] < 0)
    assert rr.closed(main_job)["crosswalk_yield"]


# -- the fixes close them ---------------------------------------------------------------------
@pytest.mark.parametrize("experiment", sorted(FIXES))
def test_experiment_composes_and_builds(experiment):
    cfg = compose("train", [f"experiment={experiment}"])
    laptop = compose("train", [])
    for name in FIXES[experiment]:
        assert cfg.reward.terms[name] > 0
    assert cfg.env.params == laptop.env.params and cfg.model == laptop.model  # the main job's
    # the main job's observation sizes apply to whichever encoder the experiment selects
    sizes = (cfg.obs.max_objects, cfg.obs.max_road)
    assert sizes == (laptop.obs.max_objects, laptop.obs.max_road) == (16, 64)
    rules = experiment in OBSERVES_RULES
    assert cfg.obs["_target_"] == ("selfplaydrive.obs.RulesEncoder" if rules else laptop.obs["_target_"])
    _need_terms(FIXES[experiment])
    env = build_env(cfg)
    assert set(FIXES[experiment]) <= set(env.term_names)
    assert (type(env.encoder).__name__ == "RulesEncoder") == rules, type(env.encoder)


@pytest.mark.parametrize(
    "experiment,loophole",
    [
        ("fix_red_light", "red_intersection"),
        ("fix_stop_sign", "stop_sign"),
        ("fix_crosswalk_yield", "crosswalk_yield"),
        ("fix_wrong_way", "wrong_way"),
    ],
)
def test_fix_closes_its_loophole(town, experiment, loophole):
    _need_terms(FIXES[experiment])
    results = rr.compare(compose("train", [f"experiment={experiment}"]), [loophole], count=3, maps=[town])
    assert rr.closed(results) == {loophole: True}
    d = {r.driver: r for r in results}
    good = next(r for r in results if r.compliant)
    if loophole != "crosswalk_yield":  # see test_crosswalk_yield_spares_the_waiting_driver
        assert np.all(good.terms[loophole] == 0)  # the compliant driver pays nothing
    for r in results:
        if r.driver == "no_yield":  # it hits the pedestrian: ended by the collision, or it pays
            assert np.all((r.terms[loophole] < 0) | (r.terms["collision"] < 0))
        elif not r.compliant and r.driver != "run":
            assert np.all(r.terms[loophole] < 0), f"{r.driver}: {r.terms[loophole]}"
    if loophole == "red_intersection":
        assert np.all(d["run"].terms[loophole] < 0)  # in its own lane it enters on red as well


def test_crosswalk_yield_spares_the_waiting_driver(town):
    _need_terms(["crosswalk_yield"])
    cfg = compose("train", ["experiment=fix_crosswalk_yield"])
    results = rr.compare(cfg, ["crosswalk_yield"], count=8, maps=[town])
    good = next(r for r in results if r.compliant)
    assert good.outcomes == ["stopped"] * 8
    # The suite's waiting driver sometimes goes while the pedestrian is still within the grown
    # crosswalk (1 of these 8 scenarios with the 0.5 m margin of obs/rule_features.py, 3 of 8
    # with 1.0 m): most waits cost nothing.
    assert np.mean(good.terms["crosswalk_yield"] == 0.0) >= 0.75


def test_fix_all_closes_every_loophole(town):
    _need_terms(FIXES["fix_all"])
    results = rr.compare(compose("train", ["experiment=fix_all"]), count=3, maps=[town])
    assert all(rr.closed(results).values()), rr.table(results)


def test_fix_stop_sign_on_tartu():
    path = shared_map("tartu_lanelet2/tartu_demo_l.osm")
    _need_terms(["stop_sign"])
    cfg = compose("train", ["experiment=fix_stop_sign"])
    results = rr.compare(cfg, ["stop_sign"], count=3, maps=[load_map(str(path))])
    assert rr.closed(results) == {"stop_sign": True}, rr.table(results)


# -- the script -------------------------------------------------------------------------------
def _script(*args: str, env: dict[str, str] | None = None) -> str:
    out = subprocess.run(
        [sys.executable, str(REPO / "benchmarks" / "reward_landscape.py"), *args],
        capture_output=True,
        text=True,
        cwd=REPO,
        env={**os.environ, "PYTHONPATH": str(REPO), **(env or {})},
        timeout=300,
    )
    assert out.returncode == 0, out.stderr
    return out.stdout


def test_script_prints_the_table():
    text = _script("--rules", "--count", "2", "--loopholes", "red_intersection")
    assert "| red_intersection | comply | 2 |" in text
    assert "| red_intersection | bypass | 2 |" in text
    assert "closed (every rule breaker earns less than the compliant driver): red_intersection NO" in text


def test_script_skips_a_missing_map(tmp_path):
    text = _script("--rules", "map=tartu", env={"SELFPLAYDRIVE_SHARED_MAPS": str(tmp_path)})
    assert text.startswith(f"skipped: map file {tmp_path}/tartu_lanelet2/tartu_demo_l.osm not present")
