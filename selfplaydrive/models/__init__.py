"""Torch policy models (paper section 3): Deep Sets + LSTM and the FiLM-conditioned Transformer.

This is the only subpackage of selfplaydrive that imports torch. Both models take the env's
`ObsLayout` and the MultiDiscrete action sizes, and share one interface (`PolicyModel`).
"""

from selfplaydrive.models.common import (
    ObsSplitter,
    PolicyModel,
    count_parameters,
    entropy,
    log_prob,
    sample_actions,
    split_logits,
)
from selfplaydrive.models.deepsets import DeepSetsModel
from selfplaydrive.models.pooling import masked_max
from selfplaydrive.models.transformer import TransformerModel

__all__ = [
    "DeepSetsModel",
    "ObsSplitter",
    "PolicyModel",
    "TransformerModel",
    "count_parameters",
    "entropy",
    "log_prob",
    "masked_max",
    "sample_actions",
    "split_logits",
]
