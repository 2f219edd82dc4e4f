"""`PPOConfig`: every hyperparameter of the library's own PPO trainer (paper section 3).

The dataclass is the config schema: a Hydra `trainer/ppo.yaml` lists these keys, the builder
passes them as keyword arguments, and nothing else reads configuration behind its back
(DESIGN.md principle 6). `validate` runs in `__post_init__`, so a bad value fails at
construction with the key, the value and what was expected.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any

from selfplaydrive.errors import ConfigError
from selfplaydrive.trainers.callbacks import callback_name

PRECISIONS = ("auto", "fp32", "bf16")


@dataclass
class PPOConfig:
    """Hyperparameters of PPO-clip with GAE, recurrent (BPTT) minibatches over agent slots.

    Counting: one *slot-step* is one agent slot of one world advanced by one env step, active or
    not; a rollout holds `rollout_length * env.num_agents` slot-steps, and only the active ones
    (the agent acted) enter the losses.
    """

    total_steps: int = 50_000_000
    """Training budget in slot-steps; the number of updates is
    `total_steps // (rollout_length * env.num_agents)` (at least 1)."""

    rollout_length: int = 64
    """Env steps collected per update; also the BPTT horizon of the LSTM (sequences are never
    cut inside a rollout)."""

    learning_rate: float = 3e-4
    """Adam step size at the start of training."""

    anneal_lr: bool = True
    """Decay the learning rate linearly to 0 over the updates."""

    adam_eps: float = 1e-5
    """Adam epsilon (1e-5 rather than torch's 1e-8, as in common PPO implementations)."""

    gamma: float = 0.99
    """Discount factor per 0.1 s step (horizon about 10 s)."""

    gae_lambda: float = 0.95
    """GAE lambda: 0 is one-step TD, 1 is the Monte-Carlo return."""

    num_epochs: int = 4
    """Passes over each rollout."""

    num_minibatches: int = 4
    """Minibatches per epoch; the rollout is split over agent slots, each minibatch holding
    whole (rollout_length,) sequences so the LSTM sees them in order."""

    clip_coef: float = 0.2
    """PPO ratio clip epsilon: the policy term uses clip(ratio, 1 - eps, 1 + eps)."""

    clip_value: bool = True
    """Also clip the value update around the rollout's value (loss = max of clipped and
    unclipped squared errors)."""

    value_clip_coef: float = 0.2
    """Clip range of the value change when `clip_value` is set (in return units)."""

    norm_adv: bool = True
    """Normalise advantages to zero mean, unit std per minibatch (active slots only)."""

    norm_returns: bool = False
    """Divide every reward by the running standard deviation of the discounted return before
    GAE (`ppo/returns.py`), so that values and their clipping live near unit scale whatever the
    reward weights. Logged returns and evaluations keep the env's own rewards."""

    ent_coef: float = 0.005
    """Weight of the entropy bonus (subtracted from the loss) at the first update."""

    ent_coef_final: float | None = None
    """Anneal the entropy bonus linearly from `ent_coef` towards this weight, on the learning
    rate's schedule: update u of U uses `ent_coef_final + (ent_coef - ent_coef_final) * (1 - u / U)`
    (logged as `charts/ent_coef`). None keeps `ent_coef` throughout."""

    vf_coef: float = 0.5
    """Weight of the value loss."""

    max_grad_norm: float = 0.5
    """Clip the global gradient norm to this value (<= 0 disables clipping)."""

    target_kl: float | None = None
    """Stop the epochs of an update early once the approximate KL exceeds this (None: never)."""

    seed: int = 0
    """Seed of torch (action sampling, init done by the caller) and of the env's reset; rank r
    of a torchrun job uses `seed + r`."""

    device: str = "auto"
    """"auto" (cuda when available, else cpu), "cpu", "cuda" or "cuda:N"; under torchrun every
    rank uses cuda:LOCAL_RANK when cuda is available."""

    precision: str = "auto"
    """Autocast dtype of forward passes: "fp32", "bf16" (torch.autocast) or "auto" (bf16 on
    cuda, fp32 on cpu). Losses, GAE and storage stay float32."""

    host_register: bool = True
    """On CUDA, page-lock the env's buffers in place (cudaHostRegister) so that uploads read
    them directly; false, or where registration fails: copy through pinned staging buffers."""

    torch_threads: int = 0
    """torch intra-op threads on the CPU (0 leaves torch's default)."""

    compile: bool = False
    """`torch.compile` the model's set pooling (models with `compile_pooling`: the Deep Sets).
    Needs a C++ compiler; the first updates compile (43 s with an empty inductor cache, 5 s
    with a warm one), and the main job's updates then ran only 1.02x faster on a 2-core CPU
    (docs/training.md, "Speed")."""

    overlap_collection: bool = False
    """Collect the next rollout in a second thread during the current update's last epoch, so
    that the simulator and the policy's inference run on one core while the update runs on
    another. The next rollout is collected by the weights at the start of that epoch (one epoch
    behind the next update's start; PPO's ratio to the stored log-probabilities accounts for
    it). The schedule is fixed, so a seed gives the same run every time; it is another run than
    with false. Switched off, with a warning, under torchrun (the collector's collectives
    would race the update's)."""

    update_threads: int = 1
    """Threads that compute each minibatch's gradient, each on a part of its agent slots (a
    replica of the model per extra thread; `ppo/parallel.py`). The parts' losses are scaled so
    that their gradients add up to the minibatch's: the same update up to float rounding, and
    the same run for a seed at any thread timing. With `overlap_collection` the minibatches
    after the collection starts run on one thread (the collector has the other core). 1 under
    torchrun, with a warning."""

    deterministic: bool = False
    """Ask torch for deterministic kernels (`torch.use_deterministic_algorithms`)."""

    log_interval: int = 1
    """Write TensorBoard scalars every this many updates."""

    checkpoint_interval: int = 50
    """Save a checkpoint every this many updates (0: only at the end)."""

    keep_checkpoints: int = 3
    """Periodic checkpoints kept on disk (older ones are deleted; the last one always stays)."""

    eval_episodes: int = 64
    """World episodes of the final evaluation summary (0 skips it)."""

    eval_max_steps: int = 5_000
    """Cap on env steps of the final evaluation (it stops earlier when enough episodes ended)."""

    eval_deterministic: bool = False
    """Final evaluation takes the most likely action instead of sampling."""

    eval_fixed_coefficients: bool = True
    """Evaluate a second time, from the same seed, under the paper's evaluation protocol
    (section 5: every reward coefficient at its fixed evaluation value, training curricula off;
    `eval.json` key `fixed_eval_coefficients`). Skipped when training already uses the fixed
    coefficients (`reward=eval`). Each world's first episode starts from the same layout as in
    the first evaluation; coefficients, hidden gains and later episodes are drawn anew."""

    progress_bar: bool = True
    """Show a tqdm progress bar with SPS and ETA (rank 0 only)."""

    callbacks: list[Any] = field(default_factory=list)
    """Objects with any of the hooks of `selfplaydrive.trainers.callbacks` (on_start, on_step,
    on_update, on_end), or config mappings with a `_target_` that the trainer instantiates."""

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Raise ConfigError naming the key, the value and the expected range."""
        _positive_ints(self, "total_steps", "rollout_length", "num_epochs", "num_minibatches", "log_interval")
        _positive_ints(self, "update_threads")
        _non_negative_ints(self, "checkpoint_interval", "eval_episodes", "eval_max_steps", "torch_threads")
        if self.keep_checkpoints < 1:
            _bad("keep_checkpoints", self.keep_checkpoints, "an int >= 1")
        for name in ("learning_rate", "adam_eps", "clip_coef", "value_clip_coef"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                _bad(name, v, "a finite number > 0")
        for name in ("gamma", "gae_lambda"):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                _bad(name, v, "a number in [0, 1]")
        for name in ("ent_coef", "vf_coef"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) >= 0):
                _bad(name, getattr(self, name), "a finite number >= 0")
        final = self.ent_coef_final
        if final is not None and not (_is_number(final) and math.isfinite(final) and final >= 0):
            _bad("ent_coef_final", final, "None or a finite number >= 0")
        if self.target_kl is not None and not self.target_kl > 0:
            _bad("target_kl", self.target_kl, "None or a number > 0")
        if not isinstance(self.host_register, bool):
            _bad("host_register", self.host_register, "true or false")
        if not isinstance(self.norm_returns, bool):
            _bad("norm_returns", self.norm_returns, "true or false")
        if not isinstance(self.overlap_collection, bool):
            _bad("overlap_collection", self.overlap_collection, "true or false")
        if not isinstance(self.compile, bool):
            _bad("compile", self.compile, "true or false")
        if self.precision not in PRECISIONS:
            _bad("precision", self.precision, f"one of {PRECISIONS}")
        if not isinstance(self.callbacks, list | tuple):
            _bad("callbacks", self.callbacks, "a list of callback objects or _target_ mappings")
        if not (self.device == "auto" or self.device == "cpu" or self.device.startswith("cuda")):
            _bad("device", self.device, "'auto', 'cpu', 'cuda' or 'cuda:N'")

    def entropy_weight(self, remaining: float) -> float:
        """Entropy-bonus weight when a share `remaining` of the updates is left (1 at the
        first update, 1/U at the last, the learning rate's factor under `anneal_lr`)."""
        if self.ent_coef_final is None:
            return self.ent_coef
        return self.ent_coef_final + (self.ent_coef - self.ent_coef_final) * remaining

    def to_dict(self) -> dict[str, object]:
        """Plain dict of every field (for the run folder and checkpoints); callbacks appear as
        their `module.Class` names, so the dict stays plain data."""
        out = {f.name: getattr(self, f.name) for f in fields(self)}
        out["callbacks"] = [callback_name(c) for c in self.callbacks]
        return out

    @classmethod
    def from_dict(cls, values: dict[str, object]) -> PPOConfig:
        """Build from a mapping, rejecting unknown keys by name."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ConfigError(f"PPOConfig: unknown key(s) {unknown}; expected keys from {sorted(known)}")
        return cls(**values)


def _bad(name: str, value: object, expected: str) -> None:
    raise ConfigError(f"PPOConfig.{name} = {value!r}: expected {expected}")


def _is_number(v: object) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def _positive_ints(cfg: PPOConfig, *names: str) -> None:
    for name in names:
        v = getattr(cfg, name)
        if isinstance(v, bool) or not isinstance(v, int) or v < 1:
            _bad(name, v, "an int >= 1")


def _non_negative_ints(cfg: PPOConfig, *names: str) -> None:
    for name in names:
        v = getattr(cfg, name)
        if isinstance(v, bool) or not isinstance(v, int) or v < 0:
            _bad(name, v, "an int >= 0")
