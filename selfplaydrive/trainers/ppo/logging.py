"""Run loggers: where a training run's scalars go (rank 0 of a job only).

Every logger shows the tqdm progress bar and prints text lines; they differ in where scalars go:

| config (`logger=`) | class | scalars written to |
|---|---|---|
| `tensorboard` (default) | `TensorBoardLogger` (= `RunLogger`) | `<run_dir>/tb/` event files |
| `jsonl` | `JsonlLogger` | `<run_dir>/metrics.jsonl`, a JSON line per `scalars` call |
| `none` | `ProgressLogger` | nowhere (progress bar and text only) |

The contract the trainers use is small: `scalars(values, step)`, `progress(updates, values)`,
`text(message)`, `close()`. A logger of your own needs only those four methods and a
constructor taking the keyword arguments in `LOGGER_ARGS`, which the trainer fills at run
time (the config lists only the other arguments, with `_partial_: true`).

Optional: `truncate(step)`, called by `train_run` when a run resumes from a checkpoint taken at
`step`, drops what an earlier attempt logged after it, so a resumed run has no duplicate rows.

Reproducibility: every logged value is a function of the seed and the config except the tags in
`WALL_CLOCK_TAGS` (throughput, and the JSONL line's `time`), which two identical runs differ in.
"""

from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path
from typing import Any, Protocol

from selfplaydrive._optional import requires_extra

# label on the progress bar -> metric keys, first present wins: the sliding window of recent
# episodes (`recent/*`, PPOTrainer) is steadier than one update's few finished episodes
PROGRESS_KEYS = {
    "sps": ("sps",),
    "return": ("recent/return_mean", "return_mean"),
    "wp_completion": ("recent/waypoint_completion", "waypoint_completion"),
}
# constructor arguments every logger takes from the trainer, never from YAML
LOGGER_ARGS = ("run_dir", "total_updates", "progress_bar", "enabled", "initial")
# values that depend on the wall clock, not on the seed: leave them out when comparing runs
WALL_CLOCK_TAGS = ("time", "charts/sps", "charts/collect_sps", "charts/slot_sps")


class Logger(Protocol):
    """What a trainer calls on its logger."""

    def scalars(self, values: dict[str, float], step: int) -> None: ...

    def progress(self, updates: int, values: dict[str, float]) -> None: ...

    def text(self, message: str) -> None: ...

    def close(self) -> None: ...


def scalar_tags(values: dict[str, Any]) -> dict[str, float]:
    """The finite numeric values of `values` under their tag names: keys with a slash keep
    their group (`losses/policy`), others go under `charts/` (`sps` -> `charts/sps`)."""
    out = {}
    for key, value in values.items():
        try:
            v = float(value)
        except (TypeError, ValueError):
            continue  # SB3 records a few strings; they are not scalars
        if math.isfinite(v):
            out[key if "/" in key else f"charts/{key}"] = v
    return out


class ProgressLogger:
    """`logger=none`: the progress bar and text lines, no scalar files.

    Args:
        run_dir: Run folder (unused here; subclasses write into it).
        total_updates: Length of the progress bar.
        progress_bar: Show the bar (tqdm on stderr; its ETA follows the update rate).
        enabled: False on ranks other than 0: every method does nothing.
        initial: Updates already done (a resumed run).
    """

    def __init__(
        self,
        run_dir: str | Path | None = None,
        total_updates: int = 0,
        progress_bar: bool = True,
        enabled: bool = True,
        initial: int = 0,
    ) -> None:
        self.enabled = enabled
        self.run_dir = None if run_dir is None else Path(run_dir)
        self.bar = None
        if enabled and progress_bar:
            from tqdm.auto import tqdm

            self.bar = tqdm(total=total_updates, initial=initial, unit="update", dynamic_ncols=True)

    def scalars(self, values: dict[str, float], step: int) -> None:
        """Write every finite value as a scalar at `step` (global slot-step count); see
        `scalar_tags` for the tag names."""
        if self.enabled:
            tags = scalar_tags(values)
            if tags:
                self._write(tags, int(step))

    def _write(self, tags: dict[str, float], step: int) -> None:
        """Store `tags` at `step` (nothing here)."""

    def progress(self, updates: int, values: dict[str, float]) -> None:
        """Advance the bar by `updates` and show SPS, return and waypoint completion."""
        if self.bar is None:
            return
        shown = {}
        for label, keys in PROGRESS_KEYS.items():
            found = [values[k] for k in keys if k in values and math.isfinite(values[k])]
            if found:
                shown[label] = f"{float(found[0]):.3g}"
        self.bar.set_postfix(shown, refresh=False)
        self.bar.update(updates)

    def text(self, message: str) -> None:
        """Print a line without breaking the bar (a full bar is closed first: redrawn under
        the line, it would show twice at the end of a run)."""
        if not self.enabled:
            return
        if self.bar is not None and self.bar.total and self.bar.n >= self.bar.total:
            self.bar.close()
            self.bar = None
        if self.bar is not None:
            self.bar.write(message)
        else:
            print(message)

    def truncate(self, step: int) -> None:
        """Forget what was logged after `step` (a resumed run; nothing is stored here)."""

    def close(self) -> None:
        """Close the bar and flush what was written."""
        if self.bar is not None:
            self.bar.close()
            self.bar = None


class TensorBoardLogger(ProgressLogger):
    """`logger=tensorboard` (the default): scalars to TensorBoard event files in
    `<run_dir>/<subdir>`, plus the progress bar.

    Args:
        subdir: Folder inside the run folder for the event files.
        flush_secs: Seconds between flushes of the event file to disk.
        run_dir, total_updates, progress_bar, enabled, initial: see `ProgressLogger`
            (`run_dir=None` writes no event file).
    """

    def __init__(
        self,
        run_dir: str | Path | None = None,
        total_updates: int = 0,
        progress_bar: bool = True,
        enabled: bool = True,
        initial: int = 0,
        subdir: str = "tb",
        flush_secs: float = 120.0,
    ) -> None:
        super().__init__(run_dir, total_updates, progress_bar, enabled, initial)
        self.writer = None
        self.log_dir = None if run_dir is None else Path(run_dir) / subdir
        self.flush_secs = int(flush_secs)
        if enabled and run_dir is not None:
            self.writer = self._open()

    def _open(self, purge_step: int | None = None) -> Any:
        with requires_extra("train"):  # torch.utils.tensorboard needs the tensorboard package
            from torch.utils.tensorboard import SummaryWriter

        return SummaryWriter(log_dir=str(self.log_dir), flush_secs=self.flush_secs, purge_step=purge_step)

    def truncate(self, step: int) -> None:
        """Hide the events after `step` from TensorBoard: a new event file whose `purge_step`
        tells TensorBoard to drop later steps of the earlier files."""
        if self.writer is not None:
            self.writer.close()
            self.writer = self._open(purge_step=int(step) + 1)

    def _write(self, tags: dict[str, float], step: int) -> None:
        if self.writer is not None:
            for tag, value in tags.items():
                self.writer.add_scalar(tag, value, step)

    def close(self) -> None:
        super().close()
        if self.writer is not None:
            self.writer.flush()
            self.writer.close()
            self.writer = None


RunLogger = TensorBoardLogger  # the name the trainers used before the logger group existed


class JsonlLogger(ProgressLogger):
    """`logger=jsonl`: scalars appended as JSON lines to `<run_dir>/<filename>`, plus the
    progress bar. Each line is `{"step": slot-steps, "time": unix seconds, "<tag>": value, ...}`
    with the same tag names as TensorBoard (`charts/sps`, `losses/policy`, `term/collision` ...),
    so it needs no TensorBoard to read: `pandas.read_json(path, lines=True)`.

    Args:
        filename: File inside the run folder (appended to, so a resumed run continues it).
        run_dir, total_updates, progress_bar, enabled, initial: see `ProgressLogger`
            (`run_dir=None` writes no file).
    """

    def __init__(
        self,
        run_dir: str | Path | None = None,
        total_updates: int = 0,
        progress_bar: bool = True,
        enabled: bool = True,
        initial: int = 0,
        filename: str = "metrics.jsonl",
    ) -> None:
        super().__init__(run_dir, total_updates, progress_bar, enabled, initial)
        self.file = None
        self.path = None if run_dir is None else Path(run_dir) / filename
        if enabled and self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.file = self.path.open("a", encoding="utf-8")

    def truncate(self, step: int) -> None:
        """Drop the lines with a `step` after `step` (and a half-written last line of a killed
        run), rewriting the file atomically, so a resumed run appends without duplicates."""
        if self.file is None or self.path is None:
            return
        self.file.close()
        lines = self.path.read_text(encoding="utf-8").splitlines()
        kept = [line for line in lines if _step_at_most(line, step)]
        tmp = self.path.with_name(self.path.name + ".tmp")
        tmp.write_text("".join(line + "\n" for line in kept), encoding="utf-8")
        os.replace(tmp, self.path)
        self.file = self.path.open("a", encoding="utf-8")

    def _write(self, tags: dict[str, float], step: int) -> None:
        if self.file is not None:
            self.file.write(json.dumps({"step": step, "time": round(time.time(), 3), **tags}) + "\n")
            self.file.flush()

    def close(self) -> None:
        super().close()
        if self.file is not None:
            self.file.close()
            self.file = None


def _step_at_most(line: str, step: int) -> bool:
    """The JSON line `line` is complete and logged at a step <= `step`."""
    try:
        row = json.loads(line)
    except json.JSONDecodeError:
        return False
    return isinstance(row, dict) and isinstance(row.get("step"), int) and row["step"] <= step
