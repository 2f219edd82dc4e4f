"""`RewardSettings`: every reward setting in one object, the ``reward`` config group (section 2.3).

The group holds the coefficient distributions (a `ConditioningSampler`, which the builder hands
to the spawner), the terms and their weights (a `LinearReward`), the reward constants the
kernels read (waypoint and velocity rewards, thresholds) and, derived from the ranges, the
observation scale of the coefficients (section 2.5). `upgrade_run_config` maps the layout of
configs saved before this group held everything (reward constants under ``env.params``,
``spawner.conditioning``) to this one.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Mapping
from typing import Any

from selfplaydrive.errors import ConfigError
from selfplaydrive.scenario.conditioning import PAPER, ConditioningSampler, Range
from selfplaydrive.sim.params import SimParams

# the reward constants (section 2.3): `SimParams` fields of the same names carry them to the
# kernels (_sim/reward.pyx, _sim/road.pyx for the comfort event); their paper values are the
# fields' defaults (one source), documented there and in docs/rewards.md
_CONSTANT_NAMES = (
    "waypoint_reward", "velocity_reward", "velocity_min", "center_max_angle_deg", "comfort_limit",
    "terminate_threshold", "collision_speed_gain", "center_bonus", "center_bonus_offset", "align_bonus",
)  # fmt: skip
CONSTANTS: dict[str, float] = {name: float(getattr(SimParams(), name)) for name in _CONSTANT_NAMES}
_POSITIVE = ("velocity_min", "center_max_angle_deg", "comfort_limit")
_SAMPLER = "selfplaydrive.scenario.conditioning.ConditioningSampler"
TARGET = "selfplaydrive.sim.reward_settings.RewardSettings"


class RewardSettings:
    """The reward of section 2.3: distributions, terms, constants and observation scale.

    Args:
        mode: "train" (coefficients drawn per agent) or "eval" (the fixed evaluation vector).
        waypoint_radius, collision, offroad, red_light, comfort, center_low, center_high,
            center_low_prob, center_bias, align_low, align_high, align_low_prob,
            eval_waypoint_radius, eval_center_bias: The coefficient distributions and eval
            values, as `ConditioningSampler` takes them (its defaults are the paper's).
        terms: Term name -> weight (`LinearReward`); None: the paper's eight terms, weight 1.
        waypoint_reward: Reward per reached waypoint.
        velocity_reward: Velocity term per step at full alignment.
        velocity_min: Minimum speed of the velocity term [m/s].
        center_max_angle_deg: The centre term needs |alpha| below this [deg].
        comfort_limit: Comfort event when |a_long| or |a_lat| exceeds this [m/s^2].
        terminate_threshold: C_collision / C_offroad at or above which the event ends the agent.
        collision_speed_gain: Collision and road-edge penalties scale with (1 + gain v) [s/m].
        center_bonus: Height of the centre term's bonus, bonus / exp(|B - s| - offset).
        center_bonus_offset: Offset of that bonus [m].
        align_bonus: The align term's bonus, align_bonus (1 - |alpha| / (pi / 2)).

    Raises:
        ConfigError: On a bad range, mode or constant, naming the key.
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
        terms: Mapping[str, Any] | None = None,
        waypoint_reward: float = CONSTANTS["waypoint_reward"],
        velocity_reward: float = CONSTANTS["velocity_reward"],
        velocity_min: float = CONSTANTS["velocity_min"],
        center_max_angle_deg: float = CONSTANTS["center_max_angle_deg"],
        comfort_limit: float = CONSTANTS["comfort_limit"],
        terminate_threshold: float = CONSTANTS["terminate_threshold"],
        collision_speed_gain: float = CONSTANTS["collision_speed_gain"],
        center_bonus: float = CONSTANTS["center_bonus"],
        center_bonus_offset: float = CONSTANTS["center_bonus_offset"],
        align_bonus: float = CONSTANTS["align_bonus"],
    ) -> None:
        self.conditioning = ConditioningSampler(
            mode, waypoint_radius, collision, offroad, red_light, comfort, center_low, center_high,
            center_low_prob, center_bias, align_low, align_high, align_low_prob,
            eval_waypoint_radius, eval_center_bias,
        )  # fmt: skip
        if terms is not None and not isinstance(terms, Mapping):
            raise ConfigError(f"reward.terms: expected a mapping of term name -> weight, got {terms!r}")
        self.terms = dict(terms) if terms is not None else None
        given = {
            "waypoint_reward": waypoint_reward,
            "velocity_reward": velocity_reward,
            "velocity_min": velocity_min,
            "center_max_angle_deg": center_max_angle_deg,
            "comfort_limit": comfort_limit,
            "terminate_threshold": terminate_threshold,
            "collision_speed_gain": collision_speed_gain,
            "center_bonus": center_bonus,
            "center_bonus_offset": center_bonus_offset,
            "align_bonus": align_bonus,
        }
        self.constants = {k: _check_constant(k, v) for k, v in given.items()}

    @property
    def coeff_scale(self) -> tuple[float, ...]:
        """Observation scale of the coefficients, derived from the ranges (section 2.5)."""
        return self.conditioning.observation_scale()

    def linear_reward(self) -> Any:
        """The env's `LinearReward` of `terms`, or None for the paper's default terms."""
        if self.terms is None:
            return None
        from selfplaydrive.rewards.components import LinearReward

        return LinearReward(self.terms)  # it checks the mapping and names the bad key

    def sim_params(self, params: Any = None) -> Any:
        """`params` (a `SimParams`, default the paper's) with this group's constants and scale."""
        base = params if params is not None else SimParams()
        return dataclasses.replace(base, **self.constants, coeff_scale=self.coeff_scale)


def _check_constant(name: str, value: Any) -> float:
    """`value` as a finite float (positive for the speeds, angles and limits)."""
    try:
        v = float(value)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"reward.{name}: expected a number, got {value!r}") from exc
    if not math.isfinite(v) or (name in _POSITIVE and v <= 0):
        kind = "a positive finite number" if name in _POSITIVE else "a finite number"
        raise ConfigError(f"reward.{name}: expected {kind}, got {value!r}")
    return v


def check_env_params(params: Any) -> None:
    """Raise if an ``env.params`` node sets a reward constant (they moved to ``reward``).

    Raises:
        ConfigError: Naming the key and where it lives now.
    """
    moved = [k for k in CONSTANTS if params is not None and k in params]
    if moved:
        new = ", ".join(f"env.params.{k} -> reward.{k}" for k in moved)
        raise ConfigError(f"the reward constants moved to the reward group: {new} (docs/rewards.md)")


def upgrade_run_config(cfg: Any) -> Any:
    """Map a saved config of the old layout to the reward group's, in place; returns `cfg`.

    Old layout: ``reward._target_`` the `ConditioningSampler`, the reward constants under
    ``env.params``, the sampler copied into ``spawner.conditioning``. A `UserWarning` names
    what moved. Configs of the current layout are returned unchanged.
    """
    from omegaconf import open_dict

    notes: list[str] = []
    with open_dict(cfg):
        _move_conditioning(cfg, notes)
        _move_constants(cfg, notes)
    if notes:
        warnings.warn(
            "config of the old layout (before the reward group held every reward setting), "
            "read as " + "; ".join(notes),
            UserWarning,
            stacklevel=2,
        )
    return cfg


def _reward_node(cfg: Any) -> Any:
    """``cfg.reward``, created as the paper's `RewardSettings` node when absent."""
    from omegaconf import OmegaConf

    if not OmegaConf.is_dict(cfg.get("reward")):
        cfg.reward = OmegaConf.create({"_target_": TARGET})
    return cfg.reward


def _move_conditioning(cfg: Any, notes: list[str]) -> None:
    """``spawner.conditioning`` (what the spawner drew from) into ``reward``; the sampler's
    target becomes `RewardSettings`."""
    from omegaconf import OmegaConf

    spawner = cfg.get("spawner")
    if OmegaConf.is_dict(spawner) and "conditioning" in spawner:
        drawn = spawner.conditioning
        if OmegaConf.is_dict(drawn):
            reward = _reward_node(cfg)
            for key in drawn:
                if key not in ("_target_", "terms"):  # an override made there wins
                    reward[key] = drawn[key]
        del spawner["conditioning"]
        notes.append("spawner.conditioning -> reward (the builder passes reward's sampler)")
    reward = cfg.get("reward")
    if OmegaConf.is_dict(reward) and reward.get("_target_") in (_SAMPLER, None):
        reward._target_ = TARGET
        notes.append(f"reward._target_ -> {TARGET}")


def _move_constants(cfg: Any, notes: list[str]) -> None:
    """The reward constants of ``env.params`` into ``reward``."""
    from omegaconf import OmegaConf

    env = cfg.get("env")
    params: Any = env.get("params") if OmegaConf.is_dict(env) else None
    if not OmegaConf.is_dict(params):
        return
    for key in CONSTANTS:
        if key in params:
            _reward_node(cfg)[key] = params[key]
            del params[key]
            notes.append(f"env.params.{key} -> reward.{key}")
