"""Built-in drivers: policies computed from the simulator state, not learned (rule-based,
static, random). Each takes the `VecEnv` it drives; `act()` returns (N, 2) actions in the env's
action space (docs/drivers.md)."""

from selfplaydrive.drivers.random import RandomDriver
from selfplaydrive.drivers.rule_based import DriverParams, RuleBasedDriver
from selfplaydrive.drivers.static import StaticDriver, static_actions

__all__ = ["DriverParams", "RandomDriver", "RuleBasedDriver", "StaticDriver", "static_actions"]
