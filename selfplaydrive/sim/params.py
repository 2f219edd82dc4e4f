"""`SimParams`: every constant of the simulator, with units (docs/world.md lists them).

Defaults follow the paper (section 2): dt = 0.1 s, comfort limit 3 m/s^2, traffic-light
states lasting U(0.5, 10) s. Observation sizes live in `ObsConfig` (one source of truth).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from selfplaydrive.errors import ConfigError

# observation scale of each reward coefficient (scenario.types.COEFF_NAMES order): the largest
# value the paper's sampling gives, so the observed coefficients lie in [-1, 1]. Envs derive
# theirs from their conditioning sampler's ranges (ConditioningSampler.observation_scale); this
# is what the paper's ranges give and the default when no sampler says otherwise.
COEFF_SCALE = (3.0, 1.0, 1.0, 1.0, 0.01, 2.5e-3, 0.3, 2.5e-2)


@dataclass(frozen=True)
class SimParams:
    """Simulator constants (not physics or action constants: see physics/ and sim/actions.py).

    The reward constants (comfort_limit, terminate_threshold, waypoint_reward, velocity_reward,
    velocity_min, center_max_angle_deg and the term shapes collision_speed_gain, center_bonus,
    center_bonus_offset, align_bonus) are kernel parameters kept here, but configs set them in
    the ``reward`` group (`selfplaydrive.sim.reward_settings.RewardSettings`), which the builder
    copies into this object; so does `coeff_scale`, derived from the reward group's ranges.

    Attributes:
        dt: Step length [s].
        comfort_limit: Comfort threshold on |a_long| and |a_lat| [m/s^2].
        lane_radius: Lane association looks for centerlines within this distance [m].
        terminate_threshold: C_collision / C_offroad at or above which the event ends the agent.
        waypoint_reward: Reward per reached waypoint.
        velocity_reward: Velocity reward at full alignment, per step.
        velocity_min: Minimum speed of the velocity reward [m/s].
        center_max_angle_deg: Centre reward only when |alpha| is below this [deg].
        collision_speed_gain: Collision and road-edge penalties scale with (1 + gain v) [s/m].
        center_bonus: Height of the centre term's bonus, bonus / exp(|B - s| - offset).
        center_bonus_offset: Offset of that bonus [m].
        align_bonus: The align term's bonus, align_bonus (1 - |alpha| / (pi / 2)).
        light_min: Shortest traffic-light state [s].
        light_max: Longest traffic-light state [s].
        pedestrian_end: "stand" (stay at the path end) or "vanish".
        wp_scale: Observation scale of waypoint offsets [m].
        length_scale: Observation scale of lengths [m].
        width_scale: Observation scale of widths [m].
        lateral_scale: Observation scale of the lane offset s [m].
        max_substeps: Cap on collision sub-steps per pair.
        cand_cap: Road candidates kept per agent before selecting the nearest max_road (per-world
            scratch; raised to what the collision and observation kernels write there).
        coeff_scale: Observation scale of each reward coefficient (`COEFF_NAMES` order, section
            2.5); None: the env derives it from its spawner's conditioning sampler
            (`ConditioningSampler.observation_scale`), else `COEFF_SCALE`.
    """

    dt: float = 0.1
    comfort_limit: float = 3.0
    lane_radius: float = 5.0
    terminate_threshold: float = 0.5
    waypoint_reward: float = 0.25
    velocity_reward: float = 2.5e-4
    velocity_min: float = 2.5
    center_max_angle_deg: float = 60.0
    collision_speed_gain: float = 0.1
    center_bonus: float = 0.05
    center_bonus_offset: float = 0.5
    align_bonus: float = 0.0025
    light_min: float = 0.5
    light_max: float = 10.0
    pedestrian_end: str = "stand"
    wp_scale: float = 200.0
    length_scale: float = 20.0
    width_scale: float = 5.0
    lateral_scale: float = 5.0
    max_substeps: int = 32
    cand_cap: int = 8192
    coeff_scale: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        self._check_coeff_scale()
        positive = (
            "dt",
            "comfort_limit",
            "lane_radius",
            "wp_scale",
            "length_scale",
            "width_scale",
            "lateral_scale",
        )
        for name in positive:
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ConfigError(f"sim.{name}: expected a positive finite number, got {v!r}")
        for name in ("max_substeps", "cand_cap"):
            if int(getattr(self, name)) < 1:
                raise ConfigError(f"sim.{name}: expected an integer >= 1, got {getattr(self, name)!r}")
        if not 0 < self.light_min <= self.light_max:
            raise ConfigError(
                f"sim.light_min/light_max: expected 0 < min <= max, got {self.light_min}, {self.light_max}"
            )
        if self.pedestrian_end not in ("stand", "vanish"):
            raise ConfigError(
                f"sim.pedestrian_end: expected 'stand' or 'vanish', got {self.pedestrian_end!r}"
            )

    def _check_coeff_scale(self) -> None:
        """Validate `coeff_scale` and store it as a tuple of floats (a config gives a list)."""
        if self.coeff_scale is None:
            return
        expected = f"sim.coeff_scale: expected {len(COEFF_SCALE)} positive finite numbers"
        try:
            scale = tuple(float(v) for v in self.coeff_scale)
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"{expected}, got {self.coeff_scale!r}") from exc
        if len(scale) != len(COEFF_SCALE) or not all(np.isfinite(v) and v > 0 for v in scale):
            raise ConfigError(f"{expected}, got {self.coeff_scale!r}")
        object.__setattr__(self, "coeff_scale", scale)

    def kernel_params(self) -> dict[str, object]:
        """The `Params` fields of _sim/common.pxd owned by this object."""
        d = asdict(self)
        return {
            "dt": d["dt"],
            "comfort_limit": d["comfort_limit"],
            "lane_radius": d["lane_radius"],
            "terminate_threshold": d["terminate_threshold"],
            "waypoint_reward": d["waypoint_reward"],
            "velocity_reward": d["velocity_reward"],
            "velocity_min": d["velocity_min"],
            "center_max_angle": float(np.deg2rad(d["center_max_angle_deg"])),
            "collision_speed_gain": d["collision_speed_gain"],
            "center_bonus": d["center_bonus"],
            "center_bonus_offset": d["center_bonus_offset"],
            "align_bonus": d["align_bonus"],
            "light_min": d["light_min"],
            "light_max": d["light_max"],
            "ped_vanish": int(self.pedestrian_end == "vanish"),
            "wp_scale": d["wp_scale"],
            "length_scale": d["length_scale"],
            "width_scale": d["width_scale"],
            "lateral_scale": d["lateral_scale"],
            "coeff_scale": np.asarray(
                COEFF_SCALE if self.coeff_scale is None else self.coeff_scale, dtype=np.float32
            ),
            "max_substeps": int(d["max_substeps"]),
        }
