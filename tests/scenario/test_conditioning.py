"""Reward-conditioning (section 2.3) and hidden-parameter (section 2.6) samplers."""

from __future__ import annotations

import numpy as np
import pytest

from selfplaydrive.errors import ConfigError
from selfplaydrive.scenario.conditioning import ConditioningSampler, HiddenParamSampler
from selfplaydrive.scenario.types import COEFF_NAMES, HIDDEN_PARAMS

N = 200_000


@pytest.fixture(scope="module")
def coeffs():
    return ConditioningSampler().sample(np.random.default_rng(0), N)


def col(c: np.ndarray, name: str) -> np.ndarray:
    return c[:, COEFF_NAMES.index(name)].astype(np.float64)


def test_shape_dtype_finite(coeffs):
    assert coeffs.shape == (N, len(COEFF_NAMES)) and coeffs.dtype == np.float32
    assert np.all(np.isfinite(coeffs))


@pytest.mark.parametrize(
    ("name", "lo", "hi"),
    [
        ("waypoint_radius", 1.0, 3.0),
        ("collision", 0.0, 1.0),
        ("offroad", 0.0, 1.0),
        ("red_light", 0.0, 1.0),
        ("comfort", 0.0, 0.01),
        ("center_bias", -0.3, 0.3),
    ],
)
def test_uniform_coefficients(coeffs, name, lo, hi):
    x = col(coeffs, name)
    span = hi - lo
    assert x.min() >= lo - 1e-6 * span and x.max() <= hi + 1e-6 * span
    # uniform: mean at the middle, each quarter of the range holds ~25%
    assert x.mean() == pytest.approx((lo + hi) / 2, abs=0.01 * span)
    quarters = np.histogram(x, bins=4, range=(lo, hi))[0] / N
    np.testing.assert_allclose(quarters, 0.25, atol=0.01)


@pytest.mark.parametrize(
    ("name", "low", "high"),
    [("center", (2.5e-5, 2.5e-4), (2.5e-4, 2.5e-3)), ("align", (2.5e-5, 2.5e-3), (2.5e-3, 2.5e-2))],
)
def test_bimodal_coefficients(coeffs, name, low, high):
    x = col(coeffs, name)
    assert x.min() >= low[0] * (1 - 1e-6) and x.max() <= high[1] * (1 + 1e-6)
    in_low = x < low[1]
    assert in_low.mean() == pytest.approx(0.5, abs=0.01)
    # within each mode the draw is uniform over that mode's range
    assert x[in_low].mean() == pytest.approx(np.mean(low), rel=0.02)
    assert x[~in_low].mean() == pytest.approx(np.mean(high), rel=0.02)


def test_eval_mode_is_fixed_at_training_maxima():
    c = ConditioningSampler(mode="eval").sample(np.random.default_rng(0), 4)
    expected = {
        "waypoint_radius": 3.0,
        "collision": 1.0,
        "offroad": 1.0,
        "red_light": 1.0,
        "comfort": 0.01,
        "center": 2.5e-3,
        "center_bias": 0.0,
        "align": 2.5e-2,
    }
    for name, value in expected.items():
        np.testing.assert_allclose(col(c, name), value, rtol=1e-6)


def test_eval_mode_follows_custom_ranges():
    s = ConditioningSampler(
        mode="eval", collision=(0.0, 0.5), align_high=(1e-3, 4e-2), eval_waypoint_radius=2.0
    )
    v = s.eval_vector()
    assert v[COEFF_NAMES.index("collision")] == pytest.approx(0.5)
    assert v[COEFF_NAMES.index("align")] == pytest.approx(4e-2)
    assert v[COEFF_NAMES.index("waypoint_radius")] == pytest.approx(2.0)


def test_custom_range_and_mode_share():
    c = ConditioningSampler(collision=(0.5, 0.6), center_low_prob=0.9).sample(
        np.random.default_rng(1), 50_000
    )
    assert col(c, "collision").min() >= 0.5 and col(c, "collision").max() <= 0.6
    assert (col(c, "center") < 2.5e-4).mean() == pytest.approx(0.9, abs=0.01)


def test_deterministic():
    a = ConditioningSampler().sample(np.random.default_rng(7), 10)
    b = ConditioningSampler().sample(np.random.default_rng(7), 10)
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"mode": "test"}, "mode must be one of"),
        ({"collision": (1.0, 0.0)}, "collision must be finite with low <= high"),
        ({"comfort": (0.0,)}, "comfort must be a \\(low, high\\) pair"),
        ({"center_low_prob": 1.5}, "center_low_prob must lie in"),
        ({"eval_waypoint_radius": -1.0}, "eval_waypoint_radius"),
    ],
)
def test_bad_config_raises(kwargs, match):
    with pytest.raises(ConfigError, match=match):
        ConditioningSampler(**kwargs)


def test_hidden_params():
    h = HiddenParamSampler().sample(np.random.default_rng(0), N)
    assert h.shape == (N, len(HIDDEN_PARAMS)) and h.dtype == np.float32
    for name, (lo, hi) in {
        "friction": (0.7, 1.3),
        "accel_gain": (0.9, 1.1),
        "steer_gain": (0.9, 1.1),
    }.items():
        x = h[:, HIDDEN_PARAMS.index(name)]
        assert x.min() >= lo - 1e-6 and x.max() <= hi + 1e-6
        assert x.mean() == pytest.approx((lo + hi) / 2, abs=0.005)
    with pytest.raises(ConfigError, match="friction must be positive"):
        HiddenParamSampler(friction=(0.0, 1.0))
