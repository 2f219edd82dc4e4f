"""Which finished world-episodes an evaluation counts.

Counting "the first N world-episodes to finish" from a reset is length-biased: every world's
first episode is counted, but the later ones that finish first are the short ones (episode
lengths are drawn per episode from `spawner.episode_lengths`, paper section 2.2). With 16 worlds
and 32 world-episodes, about 45 % of the counted episodes were 20 s long instead of a third,
and a policy too slow for its 20 s routes looked worse than it is. Counting the first k
episodes of every world instead samples the lengths as the spawner draws them.

Example:
    >>> first_episodes_quota(32, 16).tolist() == [2] * 16
    True
    >>> first_episodes_quota(5, 4).tolist()
    [2, 1, 1, 1]
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np


def first_episodes_quota(episodes: int, num_worlds: int) -> np.ndarray:
    """World-episodes to count per world: `episodes` spread over the worlds, the remainder to
    the lowest world indices (a world's index says nothing about its episodes' lengths).

    Args:
        episodes: World-episodes to count in all (>= 1).
        num_worlds: Worlds of the env (>= 1).

    Returns:
        (num_worlds,) int64, summing to `episodes`.
    """
    if int(episodes) < 1 or int(num_worlds) < 1:
        raise ValueError(f"episodes and num_worlds: expected >= 1, got {episodes!r} and {num_worlds!r}")
    base, extra = divmod(int(episodes), int(num_worlds))
    quota = np.full(int(num_worlds), base, dtype=np.int64)
    quota[:extra] += 1
    return quota


class FirstEpisodes:
    """Keeps the first `quota[w]` finished episodes of every world w (records of
    `VecEnv.pop_episode_stats`, which carry "world"), counted from the env's reset.

    Args:
        episodes: World-episodes to keep in all.
        num_worlds: Worlds of the env.
    """

    def __init__(self, episodes: int, num_worlds: int) -> None:
        self.quota = first_episodes_quota(episodes, num_worlds)
        self.seen = np.zeros_like(self.quota)
        self.kept: list[Mapping[str, Any]] = []

    def add(self, records: Iterable[Mapping[str, Any]]) -> None:
        """Count newly finished episodes (in the order they finished)."""
        for rec in records:
            w = int(rec["world"])
            if self.seen[w] < self.quota[w]:
                self.kept.append(rec)
            self.seen[w] += 1

    @property
    def done(self) -> bool:
        """Every world has finished its quota."""
        return bool((self.seen >= self.quota).all())
