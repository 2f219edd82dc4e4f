"""Trainer callbacks: code that runs inside `PPOTrainer.train` without editing the trainer.

Contract (docs/training.md, "Callbacks"). A callback is any object; the trainer calls each of
these methods only where the object defines it, in the order the callbacks are listed:

- `on_start(trainer)`: at the start of every `train()` call (also after a resume), before
  the first update of that call.
- `on_rollout(trainer)`: before the first env step of every training rollout (in the collector
  thread with `overlap_collection`); `trainer.global_step // trainer.slots_per_update` is the
  rollout's index, the same in every run of a seed, so what it sets follows the rollout, not
  the timing of threads. The env is not being stepped while it runs.
- `on_step(trainer)`: after every env step of a training rollout (not of the evaluation);
  `trainer.env` holds the step's results. Keep it cheap: it runs rollout_length times per
  update.
- `on_update(trainer, metrics)`: after every update, before the metrics are logged. A mapping
  it returns is merged into `metrics` (and so logged); `trainer.update_idx` counts the updates
  done, this one included.
- `on_end(trainer, metrics)`: when a `train()` call reaches `trainer.total_updates`.
- `state_dict()` / `load_state_dict(state)`: the callback's state, saved in every checkpoint
  and restored on resume. It must be plain data (tensors, NumPy arrays, numbers, strings,
  lists, tuples, dicts): checkpoints are loaded with `weights_only=True`. With
  `overlap_collection` a checkpoint holds the states taken when the last epoch of its update
  started (the collector's snapshot, which a resume collects from again), so what `on_update`
  of that update changed is not in it; `WeightAveraging.on_start` shows one way to catch up.

From Hydra, list callbacks under the trainer config, each a node with a `_target_`:

    selfplaydrive train 'trainer.callbacks=[{_target_: selfplaydrive.trainers.callbacks.DiversityCallback}]'
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from selfplaydrive.errors import ConfigError

HOOKS = ("on_start", "on_rollout", "on_step", "on_update", "on_end", "state_dict", "load_state_dict")


def build_callbacks(specs: Sequence[Any]) -> list[Any]:
    """Objects from `PPOConfig.callbacks`: mappings with a `_target_` are instantiated, other
    entries are used as they are.

    Raises:
        ConfigError: An entry that is neither a `_target_` mapping nor an object with at least
            one hook of `HOOKS`, naming its index.
    """
    out = []
    for i, spec in enumerate(specs):
        if isinstance(spec, Mapping):
            if "_target_" not in spec:
                raise ConfigError(f"trainer.callbacks[{i}] = {dict(spec)!r}: expected a node with _target_")
            from selfplaydrive.builder import instantiate

            spec = instantiate(spec)
        if not any(callable(getattr(spec, hook, None)) for hook in HOOKS):
            raise ConfigError(
                f"trainer.callbacks[{i}] = {spec!r}: expected an object with at least one of "
                f"{', '.join(HOOKS)}"
            )
        out.append(spec)
    return out


def callback_name(callback: Any) -> str:
    """`module.Class` of a callback (how config.json and checkpoints refer to it)."""
    if isinstance(callback, Mapping):
        return str(callback.get("_target_", "?"))
    kind = type(callback)
    return f"{kind.__module__}.{kind.__qualname__}"


class DiversityCallback:
    """Record behaviour-diversity data over the last `fraction` of training (paper section 5.4)
    and write it with `selfplaydrive.eval.diversity.save_diversity` when training ends.

    The recorder (`DiversityRecorder`) reads the training env after every env step of the
    window: road-edge and vehicle-collision onsets with the agents' coefficients, lateral
    offsets against the lane-centre bias, and the exposure of each coefficient bin.

    Args:
        fraction: Share of the updates, counted from the end, that are recorded (the paper: the
            last 10 %); at least one update is.
        out_dir: Folder for the PNGs, CSV tables and `diversity.json`, relative to the run folder
            (rank r > 0 of a torchrun job writes `<out_dir>.rank<r>`). Nothing is written
            without a run folder; `log()` still returns the data.
        lateral_every: Env steps between lateral-offset samples.
        exposure_every: Env steps between exposure samples.

    Attributes:
        paths: What `save_diversity` wrote (empty before the end of training).
    """

    def __init__(
        self,
        fraction: float = 0.1,
        out_dir: str = "diversity",
        lateral_every: int = 10,
        exposure_every: int = 10,
    ) -> None:
        if not (isinstance(fraction, int | float) and 0.0 < fraction <= 1.0):
            raise ConfigError(f"DiversityCallback.fraction = {fraction!r}: expected a number in (0, 1]")
        for name, value in (("lateral_every", lateral_every), ("exposure_every", exposure_every)):
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ConfigError(f"DiversityCallback.{name} = {value!r}: expected an int >= 1")
        self.fraction, self.out_dir = float(fraction), str(out_dir)
        self.lateral_every, self.exposure_every = lateral_every, exposure_every
        self.recorder: Any = None
        self.paths: dict[str, Path] = {}
        self._pending: dict[str, Any] | None = None  # a checkpoint's state, applied once the env is known

    def first_update(self, total_updates: int) -> int:
        """Index of the first recorded update (0-based) of a run of `total_updates` updates."""
        return total_updates - max(1, math.ceil(self.fraction * total_updates))

    def on_start(self, trainer: Any) -> None:
        if self.recorder is None and self._pending is not None:
            self._make_recorder(trainer.env)
            _restore_recorder(self.recorder, self._pending)
            self._pending = None

    def on_step(self, trainer: Any) -> None:
        if trainer.update_idx < self.first_update(trainer.total_updates):
            return
        if self.recorder is None:
            self._make_recorder(trainer.env)
        self.recorder.record()

    def on_update(self, trainer: Any, metrics: Mapping[str, float]) -> dict[str, float]:
        """Running event counts of the window, logged as `diversity/*` scalars."""
        if self.recorder is None:
            return {}
        log = self.recorder.log()
        return {
            "diversity/offroad_events": float(len(log.offroad_c)),
            "diversity/collision_events": float(len(log.coll_self)),
            "diversity/lateral_samples": float(len(log.lat_bias)),
        }

    def on_end(self, trainer: Any, metrics: Mapping[str, float]) -> None:
        if self.recorder is None or trainer.run_dir is None:
            return
        from selfplaydrive.eval.diversity import save_diversity

        rank = trainer.dist.rank
        folder = Path(trainer.run_dir) / (self.out_dir if rank == 0 else f"{self.out_dir}.rank{rank}")
        self.paths = save_diversity(self.recorder.log(), folder)

    def log(self) -> Any:
        """The `DiversityLog` recorded so far (None before the window started)."""
        return None if self.recorder is None else self.recorder.log()

    def state_dict(self) -> dict[str, Any]:
        """The recorded data as plain arrays (empty before the window started)."""
        if self.recorder is None:
            return dict(self._pending or {})
        log = self.recorder.log()
        state = {name: getattr(log, name) for name in _LOG_FIELDS}
        state["prev_events"] = self.recorder._prev.copy()
        state["steps"] = int(self.recorder._steps)
        return state

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        # the recorder needs the env, which on_start brings
        self.recorder = None
        self._pending = dict(state) if state else None

    def _make_recorder(self, env: Any) -> None:
        from selfplaydrive.eval.diversity import DiversityRecorder

        self.recorder = DiversityRecorder(env, self.lateral_every, self.exposure_every)


_LOG_FIELDS = (
    "offroad_c",
    "coll_self",
    "coll_partner",
    "coll_kind",
    "coll_overlap",
    "lat_bias",
    "lat_offset",
    "offroad_exposure",
    "pair_exposure",
)


def _restore_recorder(recorder: Any, state: Mapping[str, Any]) -> None:
    """Put `DiversityCallback.state_dict()` back into a fresh `DiversityRecorder`.

    The recorder keeps its data in private lists (selfplaydrive/eval/diversity.py); they are
    rebuilt here from the log's arrays, one chunk each, which `log()` concatenates unchanged.
    """
    recorder._off = [np.asarray(state["offroad_c"], dtype=np.float64)]
    recorder._coll = [
        (float(a), float(b), str(k), bool(o))
        for a, b, k, o in zip(
            state["coll_self"], state["coll_partner"], state["coll_kind"], state["coll_overlap"], strict=True
        )
    ]
    recorder._lat = [np.c_[state["lat_bias"], state["lat_offset"]].astype(np.float64)]
    recorder._off_exp = np.array(state["offroad_exposure"], dtype=np.float64)
    recorder._pair_exp = np.array(state["pair_exposure"], dtype=np.float64)
    recorder._prev = np.array(state["prev_events"], dtype=np.uint8)
    recorder._steps = int(state["steps"])


class TermWeightSchedule:
    """A reward term's weight moved linearly over training, e.g. a collision penalty that grows
    once the policy drives (docs/training.md "Callbacks"): the weight of rollout i is
    ``start + (end - start) * clip((i - begin * T) / (fraction * T), 0, 1)`` for a run of T
    updates, set on the env before the rollout's first step (`VecEnv.set_term_weight`). It
    depends only on the rollout's index, so a resumed run continues the schedule exactly; the
    final evaluation runs at the last weight. Logged as ``schedule/<term>_weight``.

    Args:
        term: A reward column of the env (`env.term_names`), e.g. "collision".
        start: Weight of the first rollout (until `begin` of the updates).
        end: Weight from `begin + fraction` of the updates on.
        fraction: Share of the updates over which the weight moves, in (0, 1].
        begin: Share of the updates before the weight starts to move, in [0, 1): a late
            ramp leaves the first part of training, where the policy learns to drive, alone.

    Raises:
        ConfigError: A weight that is not a finite number, a fraction outside (0, 1] or a
            begin outside [0, 1).
    """

    def __init__(
        self, term: str, start: float, end: float, fraction: float = 1.0, begin: float = 0.0
    ) -> None:
        for key, value in (("start", start), ("end", end)):
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ConfigError(f"TermWeightSchedule {key}: expected a finite number, got {value!r}")
        if isinstance(fraction, bool) or not isinstance(fraction, (int, float)) or not 0 < fraction <= 1:
            raise ConfigError(f"TermWeightSchedule fraction: expected a number in (0, 1], got {fraction!r}")
        if isinstance(begin, bool) or not isinstance(begin, (int, float)) or not 0 <= begin < 1:
            raise ConfigError(f"TermWeightSchedule begin: expected a number in [0, 1), got {begin!r}")
        self.term, self.start, self.end, self.fraction = str(term), float(start), float(end), float(fraction)
        self.begin = float(begin)

    def weight(self, rollout: int, total_updates: int) -> float:
        """The weight of rollout `rollout` (0-based) of a run of `total_updates` updates."""
        moved = rollout - self.begin * total_updates
        progress = min(1.0, max(0.0, moved / max(1e-9, self.fraction * total_updates)))
        return self.start + (self.end - self.start) * progress

    def on_rollout(self, trainer: Any) -> None:
        rollout = trainer.global_step // trainer.slots_per_update
        trainer.env.set_term_weight(self.term, self.weight(rollout, trainer.total_updates))

    def on_update(self, trainer: Any, metrics: Mapping[str, float]) -> dict[str, float]:
        # the weight of the rollout this update trained on (with overlap_collection the env
        # already holds the next one's)
        return {f"schedule/{self.term}_weight": self.weight(trainer.update_idx - 1, trainer.total_updates)}


class WeightAveraging:
    """The mean of the policy's weights over the last `fraction` of the updates (iterate
    averaging, Polyak and Juditsky 1992; Izmailov et al. 2018), put into the model when
    training ends, so that the final evaluation and `final.pt` use it.

    The mean can smooth out the noise of the last updates, as averaging fine-tunings did for
    the shipped policy (`trainers/soup.py`); on the main job it did not help (docs/training.md,
    "Callbacks": its policy still improves while the learning rate runs out). The sum is taken in float64
    after every update of the window (integer buffers keep their last value) and saved in
    checkpoints, so a resumed run averages exactly what an uninterrupted one does. A run
    extended past its end (a resume with a larger `total_steps`) continues from the average.
    Logged as ``averaging/updates``, the number of updates in the mean so far.

    Args:
        fraction: Share of the updates, counted from the end, whose weights are averaged, in
            (0, 1]; 1 averages every update's weights.

    Raises:
        ConfigError: A fraction outside (0, 1].
    """

    def __init__(self, fraction: float = 0.2) -> None:
        if isinstance(fraction, bool) or not isinstance(fraction, (int, float)) or not 0 < fraction <= 1:
            raise ConfigError(f"WeightAveraging fraction: expected a number in (0, 1], got {fraction!r}")
        self.fraction = float(fraction)
        self.sum: dict[str, Any] = {}
        self.count = 0
        self.last_update = 0  # the last update whose weights are in the sum

    def first_update(self, total_updates: int) -> int:
        """The first update (1-based, as `trainer.update_idx` after it) whose weights count."""
        return max(1, total_updates - max(1, round(self.fraction * total_updates)) + 1)

    def _add(self, trainer: Any) -> None:
        """Add the model's weights after update `trainer.update_idx`, once, inside the window."""
        first = self.first_update(trainer.total_updates)
        if trainer.update_idx <= self.last_update or trainer.update_idx < first:
            return
        for name, value in trainer.model.state_dict().items():
            if value.is_floating_point():
                value = value.detach().cpu().double()  # tensor methods: no torch import here
                self.sum[name] = value.clone() if name not in self.sum else self.sum[name] + value
        self.count += 1
        self.last_update = trainer.update_idx

    def on_start(self, trainer: Any) -> None:
        # With overlap_collection a checkpoint holds the callbacks' states from before the
        # update it was written after (the collector's snapshot); the model it holds is that
        # update's, so the one missing term is added here.
        self._add(trainer)

    def on_update(self, trainer: Any, metrics: Mapping[str, float]) -> dict[str, float]:
        self._add(trainer)
        return {"averaging/updates": float(self.count)}

    def average(self, trainer: Any) -> dict[str, Any]:
        """The model's state dict with every floating-point tensor replaced by its mean."""
        state = trainer.model.state_dict()
        return {
            name: (self.sum[name] / self.count).to(value.device, value.dtype) if name in self.sum else value
            for name, value in state.items()
        }

    def on_end(self, trainer: Any, metrics: Mapping[str, float]) -> None:
        if self.count:
            trainer.model.load_state_dict(self.average(trainer))

    def state_dict(self) -> dict[str, Any]:
        return {"sum": dict(self.sum), "count": self.count, "last_update": self.last_update}

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        self.sum = dict(state["sum"])
        self.count = int(state["count"])
        self.last_update = int(state["last_update"])
