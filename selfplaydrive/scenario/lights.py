"""Traffic-light randomisation at reset (paper section 2.2).

All lights are off in `all_off_prob` (50%) of episodes. Otherwise every signal group starts in
a uniformly random state (off, red, yellow, green) with U(0.5, 10) s left until its next change;
the simulator draws the later changes during the episode, each to one of the three other states
for U(0.5, 10) s (`_sim/events.pyx`), so no state lasts longer than 10 s.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from selfplaydrive.errors import ConfigError

OFF, RED, YELLOW, GREEN = 0, 1, 2, 3


class LightSampler:
    """Initial traffic-light states per signal group.

    Args:
        all_off_prob: Probability that every light is off for the whole episode.
        state_probs: Probabilities of the initial states (off, red, yellow, green).
        time_left: (low, high) [s] of the uniform time until a group's first change.

    Raises:
        ConfigError: On probabilities outside [0, 1], a state_probs of the wrong length or sum,
            or a bad time range.
    """

    def __init__(
        self,
        all_off_prob: float = 0.5,
        state_probs: Sequence[float] = (0.25, 0.25, 0.25, 0.25),
        time_left: tuple[float, float] = (0.5, 10.0),
    ) -> None:
        if not 0.0 <= all_off_prob <= 1.0:
            raise ConfigError(f"LightSampler.all_off_prob must lie in [0, 1], got {all_off_prob}")
        probs = np.asarray(state_probs, dtype=np.float64)
        if probs.shape != (4,) or np.any(probs < 0) or not np.isclose(probs.sum(), 1.0):
            raise ConfigError(
                f"LightSampler.state_probs must be 4 non-negative numbers summing to 1, got {state_probs}"
            )
        lo, hi = (float(v) for v in time_left)
        if not 0 < lo <= hi or not np.isfinite(hi):
            raise ConfigError(f"LightSampler.time_left must satisfy 0 < low <= high, got {time_left}")
        self.all_off_prob = float(all_off_prob)
        self.state_probs = probs
        self._cdf = np.cumsum(probs)
        self.time_left = (lo, hi)

    def sample(
        self, rng: np.random.Generator, num_groups: int, episode_length: float
    ) -> tuple[bool, np.ndarray, np.ndarray]:
        """Draw the initial light program.

        Args:
            rng: Seeded generator.
            num_groups: G, signal groups of the map.
            episode_length: [s]; used as the (finite) time left when all lights are off.

        Returns:
            lights_enabled, state (G,) int8, time_left (G,) float32 [s].
        """
        u = rng.random(1 + 2 * num_groups)
        if u[0] < self.all_off_prob:
            time_left = np.empty(num_groups, np.float32)
            time_left.fill(episode_length)  # np.full is several times slower on small arrays
            return False, np.zeros(num_groups, np.int8), time_left
        state = np.minimum(np.searchsorted(self._cdf, u[1 : 1 + num_groups], side="right"), 3).astype(np.int8)
        lo, hi = self.time_left
        time_left = (lo + (hi - lo) * u[1 + num_groups :]).astype(np.float32)
        return True, state, time_left
