"""Vehicle size distribution: from a bicycle to a bus (paper section 2.2).

The paper samples "dimensions ranging from a bicycle to a bus" and defers the details to its
supplementary material, which we do not have. We use a categorical mix of typical European
vehicle footprints; each draw picks a category and multiplies its nominal length and width by
independent U(1 - jitter, 1 + jitter) factors (default jitter 0.05), with the width capped at
2.55 m (the EU legal maximum for buses and trucks).

| category  | length [m] | width [m] | share |
|-----------|-----------:|----------:|------:|
| bicycle   | 1.8        | 0.6       | 0.05  |
| small car | 3.7        | 1.65      | 0.15  |
| car       | 4.5        | 1.8       | 0.45  |
| SUV / van | 5.0        | 2.0       | 0.20  |
| truck     | 8.0        | 2.5       | 0.08  |
| bus       | 12.0       | 2.55      | 0.07  |
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from selfplaydrive._sim.samplers import vehicle_sizes
from selfplaydrive.errors import ConfigError

MAX_WIDTH = 2.55  # [m] EU limit for road vehicles (Directive 96/53/EC)

#: (name, length [m], width [m], share) of each category.
DEFAULT_CATEGORIES: tuple[tuple[str, float, float, float], ...] = (
    ("bicycle", 1.8, 0.6, 0.05),
    ("small_car", 3.7, 1.65, 0.15),
    ("car", 4.5, 1.8, 0.45),
    ("suv_van", 5.0, 2.0, 0.20),
    ("truck", 8.0, 2.5, 0.08),
    ("bus", 12.0, 2.55, 0.07),
)


class VehicleSizeSampler:
    """Draws vehicle lengths and widths from a categorical mix with multiplicative jitter.

    Args:
        categories: Sequence of (name, length [m], width [m], share); shares are normalised.
        jitter: Relative jitter of length and width, U(1 - jitter, 1 + jitter).
        max_width: Cap on the jittered width [m].

    Raises:
        ConfigError: On empty categories, non-positive sizes or shares, or jitter outside [0, 0.5].
    """

    def __init__(
        self,
        categories: Sequence[Sequence[object]] = DEFAULT_CATEGORIES,
        jitter: float = 0.05,
        max_width: float = MAX_WIDTH,
    ) -> None:
        rows = [tuple(c) for c in categories]
        if not rows:
            raise ConfigError("VehicleSizeSampler.categories must not be empty")
        for row in rows:
            if len(row) != 4 or not all(float(v) > 0 for v in row[1:]):
                raise ConfigError(
                    f"each vehicle category must be (name, length > 0, width > 0, share > 0), got {row!r}"
                )
        if not 0.0 <= jitter <= 0.5:
            raise ConfigError(f"VehicleSizeSampler.jitter must lie in [0, 0.5], got {jitter}")
        self.names = tuple(str(r[0]) for r in rows)
        self.length = np.array([float(r[1]) for r in rows])
        self.width = np.array([float(r[2]) for r in rows])
        share = np.array([float(r[3]) for r in rows])
        self.probs = share / share.sum()
        self._cdf = np.cumsum(self.probs)
        self.jitter = float(jitter)
        self.max_width = float(max_width)

    def sample(self, rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Sizes of `n` vehicles.

        Returns:
            length (n,) float64 [m], width (n,) float64 [m], category index (n,) int64.
        """
        # one (3, n) draw; the kernel picks the category (first cdf entry above u[0]) and
        # computes length * (1 - j + 2 j u[1]) and min(width * (1 - j + 2 j u[2]), max_width)
        u = rng.random((3, n))
        return vehicle_sizes(u, self._cdf, self.length, self.width, self.jitter, self.max_width)
