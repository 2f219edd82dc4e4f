"""Reward terms (paper section 2.3): the registry of the eight kernel terms and Python hooks."""

from selfplaydrive.rewards.registry import TERM_NAMES, TERMS, RewardHook, RewardTerm

__all__ = ["TERMS", "TERM_NAMES", "RewardHook", "RewardTerm"]
