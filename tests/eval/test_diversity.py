"""Behaviour-diversity recorder, binning and plots (paper section 5.4)."""

from __future__ import annotations

import csv
import json
from types import SimpleNamespace

import numpy as np
import pytest
from fakeenv import one_world_env

from selfplaydrive.eval.diversity import DiversityLog, DiversityRecorder, analyse, save_diversity
from selfplaydrive.scenario.types import COEFF_NAMES

C_COLL, C_OFF, C_BIAS = (COEFF_NAMES.index(n) for n in ("collision", "offroad", "center_bias"))


def _constructed_log() -> DiversityLog:
    exp = np.full(10, 10.0)
    pairs = np.zeros((10, 10))
    pairs[0, 0] = 1.0
    pairs[0, 9] = pairs[9, 0] = 4.5  # 9 unordered (low, high) pairs, half in each cell
    pairs[5, 5] = 10.0  # 20 pairs in all
    return DiversityLog(
        offroad_c=np.array([0.05, 0.05, 0.15, 0.95, 1.0]),
        coll_self=np.array([0.05, 0.05, 0.5]),
        coll_partner=np.array([0.95, 0.02, np.nan]),
        coll_kind=np.array(["agent", "agent", "static"]),
        coll_overlap=np.array([True, True, False]),
        lat_bias=np.array([-0.28, -0.28, 0.27, 0.3]),
        lat_offset=np.array([-0.2, -0.4, 0.3, 0.1]),
        offroad_exposure=exp,
        pair_exposure=pairs,
    )


def test_binning_of_constructed_events():
    d = analyse(_constructed_log())
    off = d["offroad"]
    # 0.05, 0.05 -> bin 0; 0.15 -> bin 1; 0.95 and 1.0 (right edge included) -> bin 9
    np.testing.assert_array_equal(off["counts"], [2, 1, 0, 0, 0, 0, 0, 0, 0, 2])
    # share ratio: (2 / 5) / (10 / 100) = 4 in bin 0, (1 / 5) / 0.1 = 2 in bin 1, 0 elsewhere
    np.testing.assert_allclose(off["normalised"], [4, 2, 0, 0, 0, 0, 0, 0, 0, 4])
    col = d["collision"]
    assert col["agent_pairs"] == 2 and col["with_static"] == 1 and col["without_overlap"] == 1
    heat = col["counts"]
    assert heat[0, 0] == 1.0 and heat[0, 9] == heat[9, 0] == 0.5 and heat.sum() == 2.0
    # one collision of two low (< 0.1) vehicles among 2, both involve a low one
    assert col["share_both_below_first_edge"] == 0.5 and col["share_one_below_first_edge"] == 1.0
    assert col["pair_share_both_below_first_edge"] == pytest.approx(1 / 20)
    # (1 / 2) / (1 / 20) = 10 for two low vehicles; (0.5 / 2) / (4.5 / 20) for the mixed cell
    assert col["normalised"][0, 0] == pytest.approx(10.0)
    assert col["normalised"][0, 9] == pytest.approx((0.5 / 2) / (4.5 / 20))
    assert np.isnan(col["normalised"][1, 1])  # no such pairs on the road
    lat = d["lateral"]
    assert lat["n"][0] == 2 and lat["n"][-1] == 2 and lat["n"].sum() == 4  # B = 0.3 -> last bin
    assert lat["mean"][0] == pytest.approx(-0.3) and lat["median"][-1] == pytest.approx(0.2)
    assert np.isnan(lat["mean"][5])


def test_save_writes_png_csv_and_json(tmp_path):
    log = _constructed_log()
    paths = save_diversity(log, tmp_path / "div")
    for key in ("offroad_png", "collision_png", "lateral_png"):
        data = paths[key].read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 5000
    with paths["collision_csv"].open() as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 3 and rows[2]["partner_kind"] == "static" and rows[2]["c_collision_partner"] == "nan"
    assert float(rows[0]["c_collision_partner"]) == 0.95
    with paths["offroad_csv"].open() as f:
        assert len(list(csv.reader(f))) == 1 + 5
    j = json.loads(paths["json"].read_text())
    assert j["offroad"]["counts"] == [2, 1, 0, 0, 0, 0, 0, 0, 0, 2]
    assert j["collision"]["normalised"][1][1] == "nan"
    assert len(j["coeff_bins"]) == 11


def test_log_shape_checks():
    with pytest.raises(ValueError, match="offroad_exposure"):
        DiversityLog(offroad_exposure=np.zeros(3))
    with pytest.raises(ValueError, match="coll_partner"):
        DiversityLog(coll_self=np.zeros(2))


def _fake_env() -> SimpleNamespace:
    """One world, 4 agent slots, 1 static vehicle: agents 0 and 1 overlap (C_coll 0.05 and
    0.95), agent 2 overlaps the static vehicle, agent 3 is far away and on a road edge."""
    N = 4
    coeffs = np.zeros((N, len(COEFF_NAMES)), np.float32)
    coeffs[:, C_COLL] = [0.05, 0.95, 0.5, 0.3]
    coeffs[:, C_OFF] = [0.1, 0.2, 0.3, 0.75]
    coeffs[:, C_BIAS] = [0.1, -0.1, 0.2, 0.0]
    return one_world_env(
        (53.0, 0.5),
        events=np.array([1, 1, 1, 4], np.uint8),
        coeffs=coeffs,
        x=np.array([0.0, 3.0, 50.0, 200.0], np.float32),
        y=np.zeros(N, np.float32),
        heading=np.zeros(N, np.float32),
        lane_valid=np.array([1, 1, 0, 1], np.uint8),
        lane_alpha=np.array([0.0, 0.1, 0.0, 2.0], np.float32),
        lane_s=np.array([0.15, -0.2, 0.0, 0.4], np.float32),
    )


def test_recorder_finds_partners_and_counts_exposure():
    env = _fake_env()
    rec = DiversityRecorder(env, lateral_every=1, exposure_every=1)
    rec.record()
    rec.record()  # the same contacts persist: no new onsets
    log = rec.log()
    np.testing.assert_allclose(log.offroad_c, [0.75])
    # the 0-1 pair is logged once, from slot 0; agent 2's partner is the static vehicle
    assert list(log.coll_kind) == ["agent", "static"]
    np.testing.assert_allclose(log.coll_self, [0.05, 0.5])
    assert log.coll_partner[0] == pytest.approx(0.95) and np.isnan(log.coll_partner[1])
    assert log.coll_overlap.all()
    # lateral: agents 0 and 1 (agent 2 has no lane, agent 3 is at 2 rad > 60 deg), twice
    np.testing.assert_allclose(log.lat_bias, [0.1, -0.1, 0.1, -0.1], rtol=1e-6)
    np.testing.assert_allclose(log.lat_offset, [0.15, -0.2, 0.15, -0.2], rtol=1e-6)
    # exposure per sample: C_offroad bins 1, 2, 3, 7; C_coll bins 0, 9, 5, 3 -> 6 pairs
    np.testing.assert_array_equal(log.offroad_exposure, [0, 2, 2, 2, 0, 0, 0, 2, 0, 0])
    assert log.pair_exposure.sum() == 12 and log.pair_exposure[0, 9] == log.pair_exposure[9, 0] == 1.0
    np.testing.assert_array_equal(log.pair_exposure, log.pair_exposure.T)
    assert np.trace(log.pair_exposure) == 0  # no two agents share a bin


def test_recorder_on_a_rule_based_rollout(tmp_path):
    from selfplaydrive import make_env
    from selfplaydrive.drivers.rule_based import RuleBasedDriver

    env = make_env("default", num_worlds=1, seed=2)
    env.reset(seed=2)
    drv = RuleBasedDriver(env)
    rec = DiversityRecorder(env, lateral_every=5, exposure_every=5)
    acted = 0
    for t in range(100):
        env.step(drv.act())
        rec.record()
        acted += env.reward_mask.sum() if t % 5 == 0 else 0
    log = rec.log()
    assert log.offroad_exposure.sum() == acted
    assert len(log.lat_bias) > 100 and np.all(np.abs(log.lat_bias) <= 0.3 + 1e-6)
    assert np.median(np.abs(log.lat_offset)) < 0.5  # the rule-based driver keeps to the centre
    paths = save_diversity(log, tmp_path)
    assert all(p.exists() for p in paths.values())


def test_run_diversity_refuses_fixed_evaluation_coefficients():
    from selfplaydrive.eval.diversity import run_diversity
    from selfplaydrive.scenario.conditioning import ConditioningSampler
    from selfplaydrive.scenario.spawner import PaperSpawner

    spawner = PaperSpawner(conditioning=ConditioningSampler(mode="eval"))
    with pytest.raises(ValueError, match=r"mode 'eval'.*training distribution"):
        run_diversity("default", lambda obs, env: None, spawner=spawner, duration_s=1.0)
    with pytest.raises(ValueError, match="duration_s"):
        run_diversity("default", lambda obs, env: None, duration_s=0.0)
