"""Run logging: TensorBoard scalars and a tqdm progress bar (rank 0 of a job only)."""

from __future__ import annotations

import math
from pathlib import Path

PROGRESS_KEYS = ("sps", "return_mean", "waypoint_completion")


class RunLogger:
    """Writes scalars to `<run_dir>/tb` and shows a progress bar over updates.

    Args:
        run_dir: Run folder; None writes no TensorBoard file.
        total_updates: Length of the progress bar.
        progress_bar: Show the bar (tqdm on stderr; its ETA follows the update rate).
        enabled: False on ranks other than 0: every method does nothing.
        initial: Updates already done (a resumed run).
    """

    def __init__(
        self,
        run_dir: str | Path | None,
        total_updates: int,
        progress_bar: bool = True,
        enabled: bool = True,
        initial: int = 0,
    ) -> None:
        self.enabled = enabled
        self.writer = None
        self.bar = None
        if not enabled:
            return
        if run_dir is not None:
            from torch.utils.tensorboard import SummaryWriter

            self.writer = SummaryWriter(log_dir=str(Path(run_dir) / "tb"))
        if progress_bar:
            from tqdm.auto import tqdm

            self.bar = tqdm(total=total_updates, initial=initial, unit="update", dynamic_ncols=True)

    def scalars(self, values: dict[str, float], step: int) -> None:
        """Write every finite value as a scalar at `step` (global slot-step count).

        Keys with a slash keep their group (`losses/policy`); others go under `charts/`."""
        if self.writer is None:
            return
        for key, value in values.items():
            if value is None or not math.isfinite(float(value)):
                continue
            tag = key if "/" in key else f"charts/{key}"
            self.writer.add_scalar(tag, float(value), step)

    def progress(self, updates: int, values: dict[str, float]) -> None:
        """Advance the bar by `updates` and show SPS, return and waypoint completion."""
        if self.bar is None:
            return
        shown = {k: f"{values[k]:.3g}" for k in PROGRESS_KEYS if k in values and math.isfinite(values[k])}
        self.bar.set_postfix(shown, refresh=False)
        self.bar.update(updates)

    def text(self, message: str) -> None:
        """Print a line without breaking the bar."""
        if not self.enabled:
            return
        if self.bar is not None:
            self.bar.write(message)
        else:
            print(message)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
        if self.writer is not None:
            self.writer.flush()
            self.writer.close()
