"""Action sources for recording episodes: moved to `selfplaydrive.policies` (evaluation uses
them too); re-exported here so `from selfplaydrive.render.policies import make_policy` keeps
working."""

from selfplaydrive.policies import (
    BUILTIN,
    CheckpointPolicy,
    DriverPolicy,
    Policy,
    infer_model_spec,
    load_checkpoint,
    make_policy,
    model_from_checkpoint,
)

__all__ = [
    "BUILTIN",
    "CheckpointPolicy",
    "DriverPolicy",
    "Policy",
    "infer_model_spec",
    "load_checkpoint",
    "make_policy",
    "model_from_checkpoint",
]
