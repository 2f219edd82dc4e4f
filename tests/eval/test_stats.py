"""Interval statistics against hand-computed values (reference/metrics.md sections 2.4, 9).

Constants used in the hand computations:
z = Φ⁻¹(0.975) = 1.959964, z² = 3.841459;
χ²_{0.975}(2) = 7.377759, χ²_{0.025}(6) = 1.237344, χ²_{0.975}(8) = 17.534546;
t_{0.975}(2) = 4.302653.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from selfplaydrive.eval.stats import (
    garwood_interval,
    km_between_incidents,
    mean_estimate,
    proportion,
    rate_per_km,
    wilson_interval,
)


def test_wilson_zero_successes() -> None:
    # k = 0: lo = 0, hi = z²/(n + z²) = 3.841459 / 13.841459 = 0.277532
    lo, hi = wilson_interval(0, 10)
    assert lo == 0.0
    assert hi == pytest.approx(0.277532, abs=1e-6)


def test_wilson_half() -> None:
    # centre = (5 + z²/2)/(10 + z²) = 0.5; half = z/(10+z²)·sqrt(2.5 + z²/4)
    #        = 0.141600 · 1.860205 = 0.263405
    lo, hi = wilson_interval(5, 10)
    assert lo == pytest.approx(0.5 - 0.263405, abs=1e-5)
    assert hi == pytest.approx(0.5 + 0.263405, abs=1e-5)


def test_wilson_all_successes() -> None:
    # k = n = 10: lo = (10 + 1.920729)/13.841459 − 0.141600·sqrt(z²/4) = 0.861238 − 0.138766
    lo, hi = wilson_interval(10, 10)
    assert lo == pytest.approx(0.722472, abs=1e-5)
    assert hi == 1.0


def test_wilson_empty_and_bad_input() -> None:
    assert wilson_interval(0, 0) == (0.0, 1.0)
    p = proportion(0, 0)
    assert math.isnan(p.value) and p.denominator == 0
    with pytest.raises(ValueError, match="k=11 > n=10"):
        wilson_interval(11, 10)
    with pytest.raises(ValueError, match="k=-1"):
        wilson_interval(-1, 10)
    with pytest.raises(ValueError, match=r"confidence=1\.5"):
        wilson_interval(1, 10, confidence=1.5)
    with pytest.raises(ValueError, match=r"k=2\.5"):
        wilson_interval(2.5, 10)


def test_garwood_zero_and_three() -> None:
    # k = 0: (0, χ²_{0.975}(2)/2) = (0, 3.688879)
    assert garwood_interval(0, 1.0) == (0.0, pytest.approx(3.688879, abs=1e-6))
    # k = 3: (χ²_{0.025}(6)/2, χ²_{0.975}(8)/2) = (0.618672, 8.767273)
    lo, hi = garwood_interval(3, 1.0)
    assert lo == pytest.approx(0.618672, abs=1e-6)
    assert hi == pytest.approx(8.767273, abs=1e-6)
    # exposure scales the rate: 10 km → /10
    lo10, hi10 = garwood_interval(3, 10.0)
    assert (lo10, hi10) == (pytest.approx(0.0618672), pytest.approx(0.8767273))
    with pytest.raises(ValueError, match=r"exposure=0\.0"):
        garwood_interval(1, 0.0)


def test_km_between_zero_incidents() -> None:
    # 0 incidents over 100 km: point inf, lo = 100 / 3.688879 = 27.1085 km, hi inf
    est = km_between_incidents(0, 100.0)
    assert est.value == math.inf and est.hi == math.inf
    assert est.lo == pytest.approx(27.1085, abs=1e-4)
    assert est.incidents == 0 and est.km == 100.0


def test_km_between_three_incidents() -> None:
    # 3 incidents over 300 km: 100 km; lo = 300/8.767273 = 34.2182, hi = 300/0.618672 = 484.9085
    est = km_between_incidents(3, 300.0)
    assert est.value == 100.0
    assert est.lo == pytest.approx(34.2182, abs=1e-3)
    assert est.hi == pytest.approx(484.9085, abs=1e-2)


def test_rate_zero_exposure() -> None:
    r = rate_per_km(0, 0.0)
    assert math.isnan(r.value) and (r.lo, r.hi) == (0.0, math.inf)
    k = km_between_incidents(0, 0.0)
    assert math.isnan(k.value)
    with pytest.raises(ValueError, match=r"km=-1\.0"):
        rate_per_km(0, -1.0)


def test_mean_estimate_t_interval() -> None:
    # [1, 2, 3]: mean 2, s = 1, half = 4.302653/sqrt(3) = 2.484138; NaN entries are dropped
    m = mean_estimate(np.array([1.0, np.nan, 2.0, 3.0]))
    assert (m.value, m.n, m.std) == (2.0, 3, 1.0)
    assert m.lo == pytest.approx(2.0 - 2.484138, abs=1e-6)
    assert m.hi == pytest.approx(2.0 + 2.484138, abs=1e-6)
    assert math.isnan(mean_estimate(np.array([np.nan])).value)


def test_to_dict_is_strict_json() -> None:
    d = km_between_incidents(0, 5.0).to_dict()
    text = json.dumps(d, allow_nan=False)
    assert '"value": "inf"' in text and d["method"] == "garwood-inverted"
    assert proportion(1, 4).to_dict()["denominator"] == 4


def test_wilson_coverage_monte_carlo() -> None:
    # The 95 % Wilson interval should cover the true p close to 95 % of the time.
    rng = np.random.default_rng(0)
    n, p = 40, 0.15
    ks = rng.binomial(n, p, size=3000)
    table = {int(k): wilson_interval(int(k), n) for k in np.unique(ks)}
    cover = np.mean([table[int(k)][0] <= p <= table[int(k)][1] for k in ks])
    assert 0.92 <= cover <= 0.98


def test_garwood_coverage_is_conservative() -> None:
    # Exact Poisson intervals cover at least the nominal level (up to Monte Carlo noise).
    rng = np.random.default_rng(1)
    lam, km = 0.02, 150.0  # 3 expected events
    ks = rng.poisson(lam * km, size=3000)
    table = {int(k): garwood_interval(int(k), km) for k in np.unique(ks)}
    cover = np.mean([table[int(k)][0] <= lam <= table[int(k)][1] for k in ks])
    assert cover >= 0.94
