"""Confidence intervals and estimate records for evaluation aggregates.

Every aggregate the evaluator reports carries its numerator, its denominator and a 95 %
interval (reference/metrics.md section 9): Wilson score intervals for proportions, exact
Poisson (Garwood) intervals for event rates per km, and the Garwood interval inverted for
"km between incidents" (section 2.4).

Example:
    >>> lo, hi = wilson_interval(5, 10)
    >>> round(lo, 4), round(hi, 4)
    (0.2366, 0.7634)
    >>> est = km_between_incidents(0, 100.0)
    >>> est.value, round(est.lo, 2), est.hi
    (inf, 27.11, inf)
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from scipy import stats as _sps

__all__ = [
    "KmBetween",
    "MeanEstimate",
    "Proportion",
    "RateEstimate",
    "garwood_interval",
    "km_between_incidents",
    "mean_estimate",
    "proportion",
    "rate_per_km",
    "wilson_interval",
]


def _check_confidence(confidence: float) -> float:
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence={confidence!r}: expected a number in the open interval (0, 1)")
    return 1.0 - confidence


def _check_count(name: str, value: int) -> int:
    if isinstance(value, bool) or int(value) != value or value < 0:
        raise ValueError(f"{name}={value!r}: expected a non-negative integer count")
    return int(value)


def _json_float(x: float) -> float | str:
    """JSON has no inf/NaN; write them as strings so `json.dumps(..., allow_nan=False)` works."""
    if math.isnan(x):
        return "nan"
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return float(x)


def _to_dict(obj: Any) -> dict[str, Any]:
    return {k: _json_float(v) if isinstance(v, float) else v for k, v in asdict(obj).items()}


def wilson_interval(k: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson score interval for a binomial proportion k / n.

    With z the two-sided normal quantile, the bounds are
    ``(k + z²/2 ± z·sqrt(k(n−k)/n + z²/4)) / (n + z²)``, clipped to [0, 1].

    Args:
        k: Number of successes (events), 0 ≤ k ≤ n.
        n: Number of trials (the denominator).
        confidence: Two-sided confidence level, 0.95 by default.

    Returns:
        (lo, hi). For n = 0 the interval is (0.0, 1.0): nothing was observed, so every
        proportion is consistent with the data (this is also the formula's limit as n → 0).

    Raises:
        ValueError: If k or n is not a non-negative integer, k > n, or confidence is not in (0, 1).
    """
    alpha = _check_confidence(confidence)
    k, n = _check_count("k", k), _check_count("n", n)
    if k > n:
        raise ValueError(f"k={k} > n={n}: a proportion needs successes ≤ trials")
    if n == 0:
        return 0.0, 1.0
    z = float(_sps.norm.ppf(1.0 - alpha / 2.0))
    z2 = z * z
    centre = (k + z2 / 2.0) / (n + z2)
    half = z / (n + z2) * math.sqrt(k * (n - k) / n + z2 / 4.0)
    # k = 0 and k = n give exactly 0 and 1 analytically; clip away rounding noise.
    lo = 0.0 if k == 0 else max(0.0, centre - half)
    hi = 1.0 if k == n else min(1.0, centre + half)
    return lo, hi


def garwood_interval(k: int, exposure: float, confidence: float = 0.95) -> tuple[float, float]:
    """Exact (Garwood) interval for a Poisson rate λ = k / exposure.

    ``lo = χ²_{α/2}(2k) / (2·exposure)`` (0 when k = 0) and
    ``hi = χ²_{1−α/2}(2k+2) / (2·exposure)``.

    Args:
        k: Observed event count.
        exposure: Exposure in any unit (here [km]); must be > 0.
        confidence: Two-sided confidence level.

    Returns:
        (lo, hi) of the rate, in events per exposure unit.

    Raises:
        ValueError: On a negative or non-integer count, a non-positive or non-finite exposure, or
            a bad confidence level.
    """
    alpha = _check_confidence(confidence)
    k = _check_count("k", k)
    if not (math.isfinite(exposure) and exposure > 0.0):
        raise ValueError(f"exposure={exposure!r}: expected a finite number > 0 (e.g. km driven)")
    lo = 0.0 if k == 0 else float(_sps.chi2.ppf(alpha / 2.0, 2 * k)) / 2.0
    hi = float(_sps.chi2.ppf(1.0 - alpha / 2.0, 2 * k + 2)) / 2.0
    return lo / exposure, hi / exposure


@dataclass(frozen=True)
class Proportion:
    """A proportion with its numerator, denominator and Wilson interval.

    Attributes:
        value: numerator / denominator (NaN when the denominator is 0).
        numerator: Count of agent-episodes with the outcome.
        denominator: Count of agent-episodes where the outcome was evaluable.
        lo: Lower bound of the interval.
        hi: Upper bound of the interval.
        confidence: Two-sided confidence level of [lo, hi].
        method: Always "wilson".
    """

    value: float
    numerator: int
    denominator: int
    lo: float
    hi: float
    confidence: float = 0.95
    method: str = "wilson"

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-safe dict (inf/NaN written as strings)."""
        return _to_dict(self)


def proportion(k: int, n: int, confidence: float = 0.95) -> Proportion:
    """Build a `Proportion` k / n with its Wilson interval (value NaN when n = 0)."""
    lo, hi = wilson_interval(k, n, confidence)
    value = k / n if n > 0 else math.nan
    return Proportion(float(value), int(k), int(n), lo, hi, confidence)


@dataclass(frozen=True)
class RateEstimate:
    """A Poisson event rate per unit exposure with its Garwood interval.

    Attributes:
        value: count / exposure [events/km] (NaN when the exposure is 0).
        numerator: Event count.
        denominator: Exposure [km].
        lo: Lower interval bound [events/km].
        hi: Upper interval bound [events/km] (inf when the exposure is 0).
        confidence: Two-sided confidence level.
        method: Always "garwood".
    """

    value: float
    numerator: int
    denominator: float
    lo: float
    hi: float
    confidence: float = 0.95
    method: str = "garwood"

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-safe dict (inf/NaN written as strings)."""
        return _to_dict(self)


def rate_per_km(k: int, km: float, confidence: float = 0.95) -> RateEstimate:
    """Events per km with a Garwood interval; zero exposure gives value NaN and (0, inf)."""
    k = _check_count("k", k)
    if not (math.isfinite(km) and km >= 0.0):
        raise ValueError(f"km={km!r}: expected a finite distance ≥ 0 [km]")
    if km == 0.0:
        return RateEstimate(math.nan, k, 0.0, 0.0, math.inf, confidence)
    lo, hi = garwood_interval(k, km, confidence)
    return RateEstimate(k / km, k, float(km), lo, hi, confidence)


@dataclass(frozen=True)
class KmBetween:
    """Mean km between incidents (MKBI, reference/metrics.md section 2.4).

    The interval inverts the Garwood rate interval: ``lo = 1 / rate_hi`` and ``hi = 1 / rate_lo``.
    With zero incidents the point estimate and the upper bound are inf and the lower bound is
    ``km / (χ²_{0.975}(2)/2) = km / 3.689`` (two-sided 95 %; the one-sided "rule of three"
    would give km / 3.0).

    Attributes:
        value: km / incidents [km] (inf when incidents = 0, NaN when km = 0 too).
        incidents: Incident count (the denominator of the point estimate).
        km: Distance driven [km] (the numerator).
        lo: Lower bound [km].
        hi: Upper bound [km].
        confidence: Two-sided confidence level.
        method: Always "garwood-inverted".
    """

    value: float
    incidents: int
    km: float
    lo: float
    hi: float
    confidence: float = 0.95
    method: str = "garwood-inverted"

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-safe dict (inf/NaN written as strings)."""
        return _to_dict(self)


def km_between_incidents(k: int, km: float, confidence: float = 0.95) -> KmBetween:
    """Mean km between incidents with the inverted Garwood interval.

    Args:
        k: Incident count.
        km: Total distance driven [km], ≥ 0.
        confidence: Two-sided confidence level.

    Returns:
        A `KmBetween`. With km = 0 nothing is known: value NaN, interval (0, inf).
    """
    rate = rate_per_km(k, km, confidence)
    if km == 0.0:
        return KmBetween(math.nan, rate.numerator, 0.0, 0.0, math.inf, confidence)
    value = math.inf if k == 0 else km / k
    lo = 1.0 / rate.hi
    hi = math.inf if rate.lo == 0.0 else 1.0 / rate.lo
    return KmBetween(value, rate.numerator, float(km), lo, hi, confidence)


@dataclass(frozen=True)
class MeanEstimate:
    """Mean of a per agent-episode quantity with a Student-t interval.

    Attributes:
        value: Sample mean (NaN when n = 0).
        n: Number of agent-episodes averaged (the denominator).
        std: Sample standard deviation (ddof = 1; NaN when n < 2).
        lo: Lower bound of the t interval (NaN when n < 2).
        hi: Upper bound of the t interval (NaN when n < 2).
        confidence: Two-sided confidence level.
        method: Always "student-t".
    """

    value: float
    n: int
    std: float
    lo: float
    hi: float
    confidence: float = 0.95
    method: str = "student-t"

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-safe dict (inf/NaN written as strings)."""
        return _to_dict(self)


def mean_estimate(values: np.ndarray, confidence: float = 0.95) -> MeanEstimate:
    """Mean with ``mean ± t_{1−α/2}(n−1)·s/√n``; NaN entries are dropped (they mean "undefined").

    Args:
        values: (n,) per agent-episode values; NaN marks "not evaluable" and is excluded.
        confidence: Two-sided confidence level.

    Returns:
        A `MeanEstimate` whose `n` counts the finite values used.
    """
    alpha = _check_confidence(confidence)
    x = np.asarray(values, dtype=np.float64).ravel()
    if np.isinf(x).any():
        raise ValueError("values contain inf: a per-episode mean needs finite values (NaN = missing)")
    x = x[~np.isnan(x)]
    n = int(x.size)
    if n == 0:
        return MeanEstimate(math.nan, 0, math.nan, math.nan, math.nan, confidence)
    mean = float(x.mean())
    if n < 2:
        return MeanEstimate(mean, 1, math.nan, math.nan, math.nan, confidence)
    std = float(x.std(ddof=1))
    half = float(_sps.t.ppf(1.0 - alpha / 2.0, n - 1)) * std / math.sqrt(n)
    return MeanEstimate(mean, n, std, mean - half, mean + half, confidence)
