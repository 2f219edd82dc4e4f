"""Evaluation: per agent-episode metrics, Waymax-definition metrics and interval statistics.

Definitions: reference/metrics.md (Waymax section 1, long-form km between incidents section 2.4,
reporting with denominators and 95 % intervals section 9); user documentation: docs/metrics.md.
"""

from selfplaydrive.eval.metrics import AgentEpisode, EpisodeOutcome, aggregate, episode_outcome
from selfplaydrive.eval.stats import (
    KmBetween,
    MeanEstimate,
    Proportion,
    RateEstimate,
    garwood_interval,
    km_between_incidents,
    wilson_interval,
)

__all__ = [
    "AgentEpisode",
    "EpisodeOutcome",
    "KmBetween",
    "MeanEstimate",
    "Proportion",
    "RateEstimate",
    "aggregate",
    "episode_outcome",
    "garwood_interval",
    "km_between_incidents",
    "wilson_interval",
]
