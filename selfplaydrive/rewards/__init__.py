"""Reward terms (paper section 2.3): the registry of named terms, `LinearReward`, and the three
forms of a term (compiled `KernelTerm` from numba or Cython, Python `RewardHook`); see
docs/components.md "Write a reward term"."""

from selfplaydrive.rewards.base import RewardHook, RewardModule
from selfplaydrive.rewards.components import (
    ABI_VERSION,
    SIGNATURE,
    KernelTerm,
    LinearReward,
    TermColumn,
    describe_terms,
    get_term,
    register_term,
    registered_terms,
)
from selfplaydrive.rewards.registry import TERM_NAMES, TERMS, RewardTerm

__all__ = [
    "ABI_VERSION",
    "SIGNATURE",
    "TERMS",
    "TERM_NAMES",
    "KernelTerm",
    "LinearReward",
    "RewardHook",
    "RewardModule",
    "RewardTerm",
    "TermColumn",
    "describe_terms",
    "get_term",
    "register_term",
    "registered_terms",
]
