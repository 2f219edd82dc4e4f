"""benchmarks/obs_saturation.py: the summary's figures by hand, and the counts of a real env
checked against its observations read directly."""

from __future__ import annotations

import numpy as np
import pytest
from loadfile import ROOT, load_file

sat = load_file(ROOT / "benchmarks" / "obs_saturation.py", "obs_saturation")


def test_summary_by_hand():
    got = sat.summarize(np.array([0, 5, 16, 20]), [16, 4], wide=20)
    assert got["observations"] == 4
    assert got["mean_bodies"] == pytest.approx(10.25)
    assert got["share_at_wide"] == pytest.approx(0.25)  # one observation filled even the 20
    assert got["share_full_16"] == pytest.approx(0.5)
    assert got["mean_beyond_16"] == pytest.approx(1.0)  # (0 + 0 + 0 + 4) / 4
    assert got["share_full_4"] == pytest.approx(0.75)
    assert got["mean_beyond_4"] == pytest.approx((1 + 12 + 16) / 4)
    with pytest.raises(ValueError, match="no acting agent"):
        sat.summarize(np.array([], dtype=np.int64), [16], wide=63)


def test_counts_match_the_observations_and_respect_the_slots():
    from selfplaydrive.builder import build_env, compose

    small = ["env.num_worlds=2", "spawner.num_agents=6", "obs.max_objects=4"]
    env = build_env(compose("train", small))
    counts = sat.valid_counts(env, steps=3, seed=5)
    env.reset(seed=5)  # step 0 again: the first entries are its acting agents
    objects = env.layout.split(env.observations[env.masks])["objects"]
    direct = (objects[:, :, env.layout.feature_index("object", "valid")] > 0.5).sum(axis=1)
    np.testing.assert_array_equal(counts[: len(direct)], direct)
    assert counts.max() <= 4 and counts.size >= len(direct) and counts.size <= 3 * env.num_agents
    assert sat.main(["env.num_worlds=1", "--agents", "4", "--slots", "2", "--wide", "8", "--steps", "2"]) == 0
    with pytest.raises(SystemExit):
        sat.main(["--agents", "4", "--slots", "9", "--wide", "8"])
