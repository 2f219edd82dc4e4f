"""Reward-conditioning coefficients (paper section 2.3) and hidden dynamics parameters (section 2.6).

Each agent gets its own coefficients, drawn once per world reset, so one world holds a mix of
cautious and careless drivers. The policy observes the coefficients (section 2.5); the hidden
parameters (friction, action gains) are never observed.

Column order is `COEFF_NAMES` / `HIDDEN_PARAMS` from `selfplaydrive.scenario.types`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from selfplaydrive._sim.samplers import bimodal_uniform
from selfplaydrive.errors import ConfigError
from selfplaydrive.scenario.types import COEFF_NAMES, HIDDEN_PARAMS

# A range is a (low, high) pair or, as written in Hydra configs, a mapping {low: .., high: ..}
# so that sweeps can override one end: `reward.collision.high=0.5,1.0`.
Range = tuple[float, float] | Mapping[str, float]
_MODES = ("train", "eval")
# The paper's coefficient distributions and evaluation values (section 2.3, section 5): the
# defaults of `ConditioningSampler` and of `RewardSettings` (one source; conf/reward/paper.yaml
# writes them out for the command line, and tests compare the two)
PAPER: dict[str, Any] = {
    "waypoint_radius": (1.0, 3.0),  # D [m]
    "collision": (0.0, 1.0),
    "offroad": (0.0, 1.0),
    "red_light": (0.0, 1.0),
    "comfort": (0.0, 0.01),
    "center_low": (2.5e-5, 2.5e-4),  # C_center is bimodal: two log-spaced ranges
    "center_high": (2.5e-4, 2.5e-3),
    "center_low_prob": 0.5,
    "center_bias": (-0.3, 0.3),  # B [m], positive = right of the lane centre
    "align_low": (2.5e-5, 2.5e-3),
    "align_high": (2.5e-3, 2.5e-2),
    "align_low_prob": 0.5,
    "eval_waypoint_radius": 3.0,  # D [m] in evaluation mode
    "eval_center_bias": 0.0,
}


def _check_range(name: str, value: Range, allow_equal: bool = True) -> tuple[float, float]:
    """Validate a (low, high) pair or {low, high} mapping and return it as floats."""
    if isinstance(value, Mapping):
        unknown = set(value) - {"low", "high"}
        if unknown or len(value) != 2:
            raise ConfigError(f"{name} must have exactly the keys low and high, got {sorted(value)}")
        value = (value["low"], value["high"])
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{name} must be a (low, high) pair of numbers, got {value!r}") from exc
    if not (np.isfinite(lo) and np.isfinite(hi)) or hi < lo or (hi == lo and not allow_equal):
        raise ConfigError(f"{name} must be finite with low <= high, got ({lo}, {hi})")
    return lo, hi


class ConditioningSampler:
    """Samples per-agent reward coefficients in the order of `COEFF_NAMES` (section 2.3).

    Training mode draws every coefficient independently per agent. Evaluation mode (paper
    section 5) returns one fixed vector: every penalty/reward coefficient at the maximum of its
    training range, the lane-centre bias B = `eval_center_bias` (0) and the waypoint radius
    D = `eval_waypoint_radius` (3 m).

    Args:
        mode: "train" (random draws) or "eval" (fixed evaluation coefficients).
        waypoint_radius: D [m], U(low, high).
        collision: C_collision, U(low, high).
        offroad: C_offroad, U(low, high).
        red_light: C_red, U(low, high).
        comfort: C_comfort, U(low, high).
        center_low: C_center range of the low mode.
        center_high: C_center range of the high mode.
        center_low_prob: Probability of the low mode of C_center.
        center_bias: B [m], U(low, high); positive = right of the lane centre.
        align_low: C_align range of the low mode.
        align_high: C_align range of the high mode.
        align_low_prob: Probability of the low mode of C_align.
        eval_waypoint_radius: D [m] in eval mode.
        eval_center_bias: B [m] in eval mode.

    Raises:
        ConfigError: On an unknown mode, a malformed range or a probability outside [0, 1].
    """

    def __init__(
        self,
        mode: str = "train",
        waypoint_radius: Range = PAPER["waypoint_radius"],
        collision: Range = PAPER["collision"],
        offroad: Range = PAPER["offroad"],
        red_light: Range = PAPER["red_light"],
        comfort: Range = PAPER["comfort"],
        center_low: Range = PAPER["center_low"],
        center_high: Range = PAPER["center_high"],
        center_low_prob: float = PAPER["center_low_prob"],
        center_bias: Range = PAPER["center_bias"],
        align_low: Range = PAPER["align_low"],
        align_high: Range = PAPER["align_high"],
        align_low_prob: float = PAPER["align_low_prob"],
        eval_waypoint_radius: float = PAPER["eval_waypoint_radius"],
        eval_center_bias: float = PAPER["eval_center_bias"],
    ) -> None:
        if mode not in _MODES:
            raise ConfigError(f"ConditioningSampler mode must be one of {_MODES}, got {mode!r}")
        self.mode = mode
        self.waypoint_radius = _check_range("waypoint_radius", waypoint_radius)
        self.collision = _check_range("collision", collision)
        self.offroad = _check_range("offroad", offroad)
        self.red_light = _check_range("red_light", red_light)
        self.comfort = _check_range("comfort", comfort)
        self.center_low = _check_range("center_low", center_low)
        self.center_high = _check_range("center_high", center_high)
        self.center_bias = _check_range("center_bias", center_bias)
        self.align_low = _check_range("align_low", align_low)
        self.align_high = _check_range("align_high", align_high)
        for name, p in (("center_low_prob", center_low_prob), ("align_low_prob", align_low_prob)):
            if not 0.0 <= float(p) <= 1.0:
                raise ConfigError(f"{name} must lie in [0, 1], got {p}")
        self.center_low_prob = float(center_low_prob)
        self.align_low_prob = float(align_low_prob)
        if not (np.isfinite(eval_waypoint_radius) and eval_waypoint_radius > 0):
            raise ConfigError(
                f"eval_waypoint_radius must be a positive number [m], got {eval_waypoint_radius}"
            )
        self.eval_waypoint_radius = float(eval_waypoint_radius)
        self.eval_center_bias = float(eval_center_bias)
        self._lo, self._hi = self._lo_hi()  # the ranges are fixed at construction

    def eval_vector(self) -> np.ndarray:
        """(len(COEFF_NAMES),) float32: the fixed evaluation coefficients (paper section 5)."""
        values = {
            "waypoint_radius": self.eval_waypoint_radius,
            "collision": self.collision[1],
            "offroad": self.offroad[1],
            "red_light": self.red_light[1],
            "comfort": self.comfort[1],
            "center": max(self.center_low[1], self.center_high[1]),
            "center_bias": self.eval_center_bias,
            "align": max(self.align_low[1], self.align_high[1]),
        }
        return np.array([values[name] for name in COEFF_NAMES], dtype=np.float32)

    def observation_scale(self) -> tuple[float, ...]:
        """The observation scale of each coefficient (`COEFF_NAMES` order, section 2.5).

        The largest magnitude the sampler can give: max |end| over the coefficient's range(s)
        (both modes of C_center and C_align) and its eval-mode value, so the observed
        coefficient `value / scale` lies in [-1, 1] for every sweep of the ranges. A coefficient
        fixed at 0 gets scale 1 (it is observed as 0). With the paper's ranges this is
        (3, 1, 1, 1, 0.01, 2.5e-3, 0.3, 2.5e-2), `selfplaydrive.sim.params.COEFF_SCALE`.
        """
        ends = {
            "waypoint_radius": (*self.waypoint_radius, self.eval_waypoint_radius),
            "collision": self.collision,
            "offroad": self.offroad,
            "red_light": self.red_light,
            "comfort": self.comfort,
            "center": (*self.center_low, *self.center_high),
            "center_bias": (*self.center_bias, self.eval_center_bias),
            "align": (*self.align_low, *self.align_high),
        }
        scale = [max(abs(float(v)) for v in ends[name]) for name in COEFF_NAMES]
        return tuple(s if s > 0 else 1.0 for s in scale)

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """Coefficients for `n` agents.

        Args:
            rng: Seeded generator; the draws are consumed in `COEFF_NAMES` order.
            n: Number of agents.

        Returns:
            (n, len(COEFF_NAMES)) float32.
        """
        if self.mode == "eval":
            return np.tile(self.eval_vector(), (n, 1))
        # one (n, 10) draw: one column per coefficient plus the two mode choices, in this order;
        # coefficient k of an agent is lo_k + (hi_k - lo_k) u_k with its (bimodal) range
        u = rng.random((n, len(COEFF_NAMES) + 2))
        return bimodal_uniform(
            u, self._lo, self._hi,
            COEFF_NAMES.index("center"), self.center_low[0], self.center_low[1], self.center_low_prob,
            COEFF_NAMES.index("align"), self.align_low[0], self.align_low[1], self.align_low_prob,
        )  # fmt: skip

    def _lo_hi(self) -> tuple[np.ndarray, np.ndarray]:
        """(C,) lower and upper bounds of each coefficient's range (the high mode of the two
        bimodal ones)."""
        ranges = {
            "waypoint_radius": self.waypoint_radius,
            "collision": self.collision,
            "offroad": self.offroad,
            "red_light": self.red_light,
            "comfort": self.comfort,
            "center": self.center_high,
            "center_bias": self.center_bias,
            "align": self.align_high,
        }
        lo = np.array([float(ranges[k][0]) for k in COEFF_NAMES])
        hi = np.array([float(ranges[k][1]) for k in COEFF_NAMES])
        return lo, hi


class HiddenParamSampler:
    """Samples the hidden per-agent dynamics parameters in `HIDDEN_PARAMS` order (section 2.6).

    Args:
        friction: Tyre-road friction coefficient mu, U(low, high).
        accel_gain: Multiplier on the acceleration action, U(low, high).
        steer_gain: Multiplier on the steering action, U(low, high).

    Raises:
        ConfigError: On a malformed range or a non-positive friction.
    """

    def __init__(
        self,
        friction: Range = (0.7, 1.3),
        accel_gain: Range = (0.9, 1.1),
        steer_gain: Range = (0.9, 1.1),
    ) -> None:
        self.friction = _check_range("friction", friction)
        self.accel_gain = _check_range("accel_gain", accel_gain)
        self.steer_gain = _check_range("steer_gain", steer_gain)
        if self.friction[0] <= 0:
            raise ConfigError(f"friction must be positive, got range {self.friction}")
        ranges = {"friction": self.friction, "accel_gain": self.accel_gain, "steer_gain": self.steer_gain}
        self._lo = np.array([ranges[k][0] for k in HIDDEN_PARAMS])  # fixed at construction
        self._span = np.array([ranges[k][1] for k in HIDDEN_PARAMS]) - self._lo

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """(n, len(HIDDEN_PARAMS)) float32 friction, accel gain, steer gain."""
        return (self._lo + self._span * rng.random((n, len(HIDDEN_PARAMS)))).astype(np.float32)
