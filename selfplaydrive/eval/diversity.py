"""Behaviour diversity against the conditioning coefficients (paper section 5.4).

`DiversityRecorder(env)` reads the env after every `step` (training or evaluation) and logs:

- road-edge onsets (rising edge of the EV_OFFROAD bit of an agent that acted) with the agent's
  C_offroad;
- vehicle-collision onsets with both vehicles' C_collision. The partner is the nearest body
  (centre distance) whose box overlaps the agent's box at the event step (separating-axis
  test, `waymax_metrics.boxes_overlap`): other agents of the world (active, kept as obstacles,
  or ended in this very step), then static vehicles (no coefficient: NaN). If no box overlaps
  (a contact found by the kernel's sub-steps only), the nearest body is taken and `overlap` is
  False. A collision between two agents is logged once (from the lower slot);
- lateral offsets: every `lateral_every` steps, the signed offset `lane_s` (+ right [m]) of every
  agent that acted with a lane and |alpha| < 60 deg, with its lane-centre bias B;
- exposure: every `exposure_every` steps, histograms of C_offroad over acting agents and of
  (C_collision, C_collision) over unordered pairs of acting agents of the same world, so event
  counts can be normalised by how common each coefficient was on the road.

`run_diversity(maps_or_env_factory, policy, ...)` drives a policy with the training
distribution of the coefficients and records every step (what `selfplaydrive eval
eval=diversity` runs); `analyse(log)` bins everything; `save_diversity(log, out_dir)` writes
the PNGs (matplotlib, Agg), CSV event tables and a JSON of the binned data. Normalised =
(share of events in a bin) / (share of exposure in the bin): 1 means "as often as the
coefficient occurs".

Limitation: an autoreset clears the event bits of a world's last step before Python sees them,
so events in the very last step of an episode are not logged (1 step in 200-400).
"""

from __future__ import annotations

import csv
import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from selfplaydrive.eval.collisions import collision_partner
from selfplaydrive.eval.metrics import EVENT_BITS
from selfplaydrive.eval.report import json_safe
from selfplaydrive.scenario.types import COEFF_NAMES

__all__ = [
    "DiversityLog",
    "DiversityRecorder",
    "analyse",
    "diversity_summary",
    "run_diversity",
    "save_diversity",
]

C_COLL, C_OFF, C_BIAS = (COEFF_NAMES.index(n) for n in ("collision", "offroad", "center_bias"))
EV_COLLIDE, EV_OFFROAD = EVENT_BITS["vehicle"], EVENT_BITS["road_edge"]
COEFF_BINS = np.linspace(0.0, 1.0, 11)  # 0.1 wide, the paper's "< 0.1" statements
BIAS_BINS = np.linspace(-0.3, 0.3, 13)  # B ~ U(-0.3, 0.3) [m]


@dataclass
class DiversityLog:
    """Events and exposure of a run (arrays grow as the recorder reads steps).

    Attributes:
        offroad_c: (E,) C_offroad of each road-edge onset.
        coll_self: (M,) C_collision of the agent that logged a vehicle collision.
        coll_partner: (M,) partner's C_collision (NaN for static vehicles).
        coll_kind: (M,) "agent" or "static".
        coll_overlap: (M,) the partner's box overlapped at the event step.
        lat_bias: (S,) bias B [m] of each lateral sample.
        lat_offset: (S,) lateral offset s [m] (+ right of the lane direction).
        offroad_exposure: (len(coeff_bins) - 1,) acting agents per C_offroad bin (summed over
            exposure samples).
        pair_exposure: (nb, nb) symmetric, unordered same-world agent pairs per
            (C_collision, C_collision) bin pair (an off-diagonal pair adds 1/2 to each cell).
        coeff_bins: Bin edges of the coefficients.
        bias_bins: Bin edges of the bias [m].
    """

    offroad_c: np.ndarray = field(default_factory=lambda: np.zeros(0))
    coll_self: np.ndarray = field(default_factory=lambda: np.zeros(0))
    coll_partner: np.ndarray = field(default_factory=lambda: np.zeros(0))
    coll_kind: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype="<U6"))
    coll_overlap: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    lat_bias: np.ndarray = field(default_factory=lambda: np.zeros(0))
    lat_offset: np.ndarray = field(default_factory=lambda: np.zeros(0))
    offroad_exposure: np.ndarray = field(default_factory=lambda: np.zeros(len(COEFF_BINS) - 1))
    pair_exposure: np.ndarray = field(default_factory=lambda: np.zeros((len(COEFF_BINS) - 1,) * 2))
    coeff_bins: np.ndarray = field(default_factory=lambda: COEFF_BINS.copy())
    bias_bins: np.ndarray = field(default_factory=lambda: BIAS_BINS.copy())

    def __post_init__(self) -> None:
        nb = len(self.coeff_bins) - 1
        if np.shape(self.offroad_exposure) != (nb,) or np.shape(self.pair_exposure) != (nb, nb):
            raise ValueError(
                f"DiversityLog: offroad_exposure {np.shape(self.offroad_exposure)} and pair_exposure "
                f"{np.shape(self.pair_exposure)} must be ({nb},) and ({nb}, {nb}) for {nb} coefficient bins"
            )
        n = len(self.coll_self)
        for name in ("coll_partner", "coll_kind", "coll_overlap"):
            if len(getattr(self, name)) != n:
                raise ValueError(f"DiversityLog.{name}: expected {n} entries like coll_self")
        if len(self.lat_bias) != len(self.lat_offset):
            raise ValueError("DiversityLog: lat_bias and lat_offset must have the same length")


class DiversityRecorder:
    """Log diversity events of a `VecEnv`; call `record()` after every `env.step`.

    Args:
        env: The `VecEnv` (read only: `state` views, `reward_mask`).
        lateral_every: Steps between lateral-offset samples.
        exposure_every: Steps between exposure samples.
        coeff_bins: Bin edges of C_offroad and C_collision.
        bias_bins: Bin edges of the bias B [m].
    """

    def __init__(
        self,
        env: Any,
        lateral_every: int = 10,
        exposure_every: int = 10,
        coeff_bins: np.ndarray = COEFF_BINS,
        bias_bins: np.ndarray = BIAS_BINS,
    ) -> None:
        if int(lateral_every) < 1 or int(exposure_every) < 1:
            raise ValueError(f"lateral_every={lateral_every}, exposure_every={exposure_every}: expected >= 1")
        self.env = env
        self.lateral_every, self.exposure_every = int(lateral_every), int(exposure_every)
        self.coeff_bins = np.asarray(coeff_bins, dtype=np.float64)
        self.bias_bins = np.asarray(bias_bins, dtype=np.float64)
        nb = len(self.coeff_bins) - 1
        self._prev = np.zeros(env.num_agents, dtype=np.uint8)
        self._steps = 0
        self._off: list[np.ndarray] = []
        self._coll: list[tuple[float, float, str, bool]] = []
        self._lat: list[np.ndarray] = []
        self._off_exp = np.zeros(nb)
        self._pair_exp = np.zeros((nb, nb))

    def record(self) -> None:
        """Read the step just taken."""
        st, acted = self.env.state, self.env.reward_mask
        ev = np.where(acted, st.events, 0).astype(np.uint8)
        onset = ev & ~self._prev
        self._prev = ev
        coeffs = st.coeffs
        off = np.flatnonzero(onset & EV_OFFROAD)
        if len(off):
            self._off.append(coeffs[off, C_OFF].astype(np.float64))
        for i in np.flatnonzero(onset & EV_COLLIDE):
            self._collision(int(i), onset)
        if self._steps % self.lateral_every == 0:
            ok = acted & st.lane_valid.astype(bool) & (np.abs(st.lane_alpha) < np.pi / 3)
            self._lat.append(np.c_[coeffs[ok, C_BIAS], st.lane_s[ok]].astype(np.float64))
        if self._steps % self.exposure_every == 0:
            self._exposure(acted, coeffs)
        self._steps += 1

    def _bin(self, c: np.ndarray) -> np.ndarray:
        return np.clip(np.searchsorted(self.coeff_bins, c, side="right") - 1, 0, len(self.coeff_bins) - 2)

    def _exposure(self, acted: np.ndarray, coeffs: np.ndarray) -> None:
        nb, A = len(self.coeff_bins) - 1, self.env.agents_per_world
        idx = np.flatnonzero(acted)
        self._off_exp += np.bincount(self._bin(coeffs[idx, C_OFF]), minlength=nb)
        w = idx // A
        counts = np.bincount(w * nb + self._bin(coeffs[idx, C_COLL]), minlength=self.env.num_worlds * nb)
        n = counts.reshape(-1, nb).astype(np.float64)
        # unordered pairs per bin pair, summed over worlds: (n^T n - diag(n)) / 2
        self._pair_exp += (n.T @ n - np.diag(n.sum(axis=0))) / 2.0

    def _collision(self, i: int, onset: np.ndarray) -> None:
        coeffs = self.env.state.coeffs
        what, j, overlap = collision_partner(self.env, i)
        if what == "agent":
            if j < i and onset[j] & EV_COLLIDE:
                return  # the pair was logged from the lower slot
            self._coll.append((float(coeffs[i, C_COLL]), float(coeffs[j, C_COLL]), "agent", overlap))
        elif what == "static":
            self._coll.append((float(coeffs[i, C_COLL]), float("nan"), "static", overlap))

    def counts(self) -> tuple[int, int]:
        """(road-edge onsets, vehicle collisions) logged so far."""
        return sum(len(a) for a in self._off), len(self._coll)

    def log(self) -> DiversityLog:
        """The events and exposure recorded so far."""
        coll = self._coll
        lat = np.concatenate(self._lat) if self._lat else np.zeros((0, 2))
        return DiversityLog(
            offroad_c=np.concatenate(self._off) if self._off else np.zeros(0),
            coll_self=np.array([c[0] for c in coll], dtype=np.float64),
            coll_partner=np.array([c[1] for c in coll], dtype=np.float64),
            coll_kind=np.array([c[2] for c in coll], dtype="<U6"),
            coll_overlap=np.array([c[3] for c in coll], dtype=bool),
            lat_bias=lat[:, 0],
            lat_offset=lat[:, 1],
            offroad_exposure=self._off_exp.copy(),
            pair_exposure=self._pair_exp.copy(),
            coeff_bins=self.coeff_bins.copy(),
            bias_bins=self.bias_bins.copy(),
        )


def _share_ratio(counts: np.ndarray, exposure: np.ndarray) -> np.ndarray:
    """(counts / Σ counts) / (exposure / Σ exposure); NaN where nothing was exposed."""
    c, e = np.asarray(counts, dtype=np.float64), np.asarray(exposure, dtype=np.float64)
    if c.sum() == 0 or e.sum() == 0:
        return np.full(c.shape, np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(e > 0, (c / c.sum()) / (e / e.sum()), np.nan)


def analyse(log: DiversityLog) -> dict[str, Any]:
    """Binned data of the three analyses of section 5.4 (plain lists, JSON-ready)."""
    cb, nb = log.coeff_bins, len(log.coeff_bins) - 1
    off_counts = np.histogram(np.clip(log.offroad_c, cb[0], cb[-1]), bins=cb)[0]
    pairs = log.coll_kind == "agent"
    a, b = np.clip(log.coll_self[pairs], cb[0], cb[-1]), np.clip(log.coll_partner[pairs], cb[0], cb[-1])
    h = np.histogram2d(a, b, bins=[cb, cb])[0]
    heat = (h + h.T) / 2.0  # symmetric: each collision adds 1/2 to (a, b) and to (b, a)
    low = cb[1]  # upper edge of the lowest bin (0.1 by default)
    both_low = np.sum((a < low) & (b < low))
    one_low = np.sum((a < low) | (b < low))
    pe = log.pair_exposure
    lat_mean, lat_q25, lat_q50, lat_q75, lat_n = _binned_stats(log.lat_bias, log.lat_offset, log.bias_bins)
    return {
        "coeff_bins": cb,
        "bias_bins": log.bias_bins,
        "offroad": {
            "counts": off_counts,
            "exposure": log.offroad_exposure,
            "normalised": _share_ratio(off_counts, log.offroad_exposure),
        },
        "collision": {
            "agent_pairs": int(pairs.sum()),
            "with_static": int((log.coll_kind == "static").sum()),
            "without_overlap": int((~log.coll_overlap).sum()),
            "counts": heat,
            "pair_exposure": pe,
            "normalised": _share_ratio(heat, pe),
            "share_both_below_first_edge": float(both_low / pairs.sum()) if pairs.sum() else float("nan"),
            "share_one_below_first_edge": float(one_low / pairs.sum()) if pairs.sum() else float("nan"),
            "pair_share_both_below_first_edge": float(pe[0, 0] / pe.sum()) if pe.sum() else float("nan"),
            "first_edge": float(low),
            "bins": nb,
        },
        "lateral": {"mean": lat_mean, "q25": lat_q25, "median": lat_q50, "q75": lat_q75, "n": lat_n},
    }


def _binned_stats(x: np.ndarray, y: np.ndarray, bins: np.ndarray) -> tuple[np.ndarray, ...]:
    nb = len(bins) - 1
    k = np.clip(np.searchsorted(bins, x, side="right") - 1, 0, nb - 1)
    out = np.full((4, nb), np.nan)
    n = np.bincount(k, minlength=nb)
    for j in np.flatnonzero(n):
        v = y[k == j]
        out[:, j] = [v.mean(), *np.percentile(v, [25, 50, 75])]
    return out[0], out[1], out[2], out[3], n


def save_diversity(log: DiversityLog, out_dir: str | Path) -> dict[str, Path]:
    """Write the PNGs, CSV tables and `diversity.json` of `log` into `out_dir`.

    Returns:
        Paths by name: offroad_png, collision_png, lateral_png, json, offroad_csv,
        collision_csv, lateral_csv.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    data = analyse(log)
    paths = {
        "json": out / "diversity.json",
        "offroad_csv": out / "offroad_events.csv",
        "collision_csv": out / "collision_events.csv",
        "lateral_csv": out / "lateral_samples.csv",
    }
    paths["json"].write_text(json.dumps(json_safe(data), indent=1, allow_nan=False) + "\n")
    _csv(paths["offroad_csv"], ["c_offroad"], zip(log.offroad_c, strict=True))
    _csv(
        paths["collision_csv"],
        ["c_collision_self", "c_collision_partner", "partner_kind", "overlap"],
        zip(log.coll_self, log.coll_partner, log.coll_kind, log.coll_overlap.astype(int), strict=True),
    )
    _csv(paths["lateral_csv"], ["bias_m", "lateral_offset_m"], zip(log.lat_bias, log.lat_offset, strict=True))
    paths.update(_plot_all(log, data, out))
    return paths


def _csv(path: Path, header: list[str], rows: Any) -> None:
    with path.open("w", newline="") as f:
        wr = csv.writer(f)
        wr.writerow(header)
        wr.writerows(rows)


def _plot_all(log: DiversityLog, data: dict[str, Any], out: Path) -> dict[str, Path]:
    """The three figures of section 5.4 as PNGs (matplotlib, Agg backend)."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    cb = log.coeff_bins
    centres = (cb[:-1] + cb[1:]) / 2
    paths = {}
    fig, ax = plt.subplots(1, 2, figsize=(9, 3.5))
    ax[0].bar(centres, data["offroad"]["counts"], width=np.diff(cb), edgecolor="k")
    ax[0].set(xlabel="C_offroad", ylabel="road-edge events", title="Road-edge events")
    ax[1].bar(centres, np.nan_to_num(data["offroad"]["normalised"]), width=np.diff(cb), edgecolor="k")
    ax[1].axhline(1.0, color="r", lw=1, ls="--")
    ax[1].set(xlabel="C_offroad", ylabel="event share / agent share", title="Normalised by coefficient")
    paths["offroad_png"] = _save(fig, out / "offroad_vs_coefficient.png")

    fig, ax = plt.subplots(1, 2, figsize=(10, 4.2))
    col = data["collision"]
    for k, (m, title) in enumerate(
        ((col["counts"], "Vehicle-vehicle collisions"), (col["normalised"], "Collision share / pair share"))
    ):
        im = ax[k].imshow(
            np.asarray(m, float).T, origin="lower", extent=(cb[0], cb[-1], cb[0], cb[-1]), cmap="viridis"
        )
        ax[k].set(xlabel="C_collision (vehicle 1)", ylabel="C_collision (vehicle 2)", title=title)
        fig.colorbar(im, ax=ax[k])
    paths["collision_png"] = _save(fig, out / "collision_heatmap.png")

    fig, ax = plt.subplots(figsize=(5, 4))
    n = len(log.lat_bias)
    pick = np.random.default_rng(0).choice(n, size=min(n, 5000), replace=False) if n else np.zeros(0, int)
    ax.scatter(log.lat_bias[pick], log.lat_offset[pick], s=2, alpha=0.2, color="tab:blue", label="samples")
    bb = log.bias_bins
    bc = (bb[:-1] + bb[1:]) / 2
    lat = data["lateral"]
    ax.plot(bc, lat["median"], "o-", color="k", label="median")
    ax.fill_between(bc, lat["q25"], lat["q75"], color="k", alpha=0.2, label="25-75 %")
    ax.plot(bb[[0, -1]], bb[[0, -1]], "r--", lw=1, label="s = B")
    ax.set(
        xlabel="lane-centre bias B [m]",
        ylabel="lateral offset s [m] (+ right)",
        title="Lateral offset vs bias",
    )
    ax.set_ylim(bb[0] - 1.0, bb[-1] + 1.0)
    ax.legend(fontsize=7)
    paths["lateral_png"] = _save(fig, out / "lateral_vs_bias.png")
    return paths


def _save(fig: Any, path: Path) -> Path:
    import matplotlib.pyplot as plt

    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def run_diversity(
    env_factory_or_maps: Any,
    policy: Callable[[np.ndarray, Any], np.ndarray],
    spawner: Any = None,
    duration_s: float = 200.0,
    num_worlds: int = 16,
    seed: int = 0,
    lateral_every: int = 10,
    exposure_every: int = 10,
    progress: Callable[[str], None] | None = None,
) -> DiversityLog:
    """Drive `policy` in every agent slot and record the diversity events of each step.

    Episodes end and autoreset as in training, so the coefficients keep being redrawn from the
    spawner's conditioning sampler: it must be the training distribution (mode "train"), else
    every agent has the same coefficients and there is nothing to bin.

    Args:
        env_factory_or_maps: Maps for `make_env` (a `RoadMap`, a spec or a list), or a factory
            `f(spawner=, num_worlds=, seed=) -> VecEnv` that uses the spawner it is given.
        policy: `policy(obs, env) -> (N, 2) actions`.
        spawner: The env's spawner (default `PaperSpawner()`: the paper's training coefficients).
        duration_s: Simulated time per world [s].
        num_worlds: Worlds stepped together.
        seed: Reset seed.
        lateral_every: Steps between lateral-offset samples (`DiversityRecorder`).
        exposure_every: Steps between exposure samples.
        progress: Called with a one-line status after every tenth of the run; None is silent.

    Returns:
        The recorded `DiversityLog`.

    Raises:
        ValueError: A non-positive duration or world count, or a spawner whose coefficients
            are the fixed evaluation ones.
    """
    from selfplaydrive.eval.longform import build_eval_env
    from selfplaydrive.scenario.spawner import PaperSpawner

    if not (np.isfinite(duration_s) and duration_s > 0):
        raise ValueError(f"diversity duration_s: expected a positive number of seconds, got {duration_s!r}")
    if int(num_worlds) < 1:
        raise ValueError(f"diversity num_worlds: expected an integer >= 1, got {num_worlds!r}")
    spawner = PaperSpawner() if spawner is None else spawner
    mode = getattr(getattr(spawner, "conditioning", None), "mode", "train")
    if mode == "eval":
        raise ValueError(
            "diversity spawner: its conditioning sampler has mode 'eval' (one fixed coefficient vector); "
            "expected the training distribution (mode 'train')"
        )
    env = build_eval_env(env_factory_or_maps, spawner, int(num_worlds), int(seed))
    steps = max(1, round(duration_s / float(env.params.dt)))
    obs = env.reset(seed=seed)
    rec = DiversityRecorder(env, lateral_every=lateral_every, exposure_every=exposure_every)
    every, start = max(1, steps // 10), time.perf_counter()
    for k in range(1, steps + 1):
        env.step(policy(obs, env))
        obs = env.observations
        rec.record()
        env.pop_episode_stats()  # not used here; dropped so the list does not grow
        if progress is not None and (k % every == 0 or k == steps):
            dt, (n_off, n_coll) = float(env.params.dt), rec.counts()
            progress(
                f"diversity: {k * dt:.1f}/{steps * dt:.1f} s simulated, {n_off} road-edge events, "
                f"{n_coll} collisions ({time.perf_counter() - start:.0f} s)"
            )
    return rec.log()


def diversity_summary(log: DiversityLog) -> dict[str, Any]:
    """The scalar results of `analyse(log)` (event counts, shares below the first bin edge) for
    a markdown table; the binned curves stay in the JSON and PNGs of `save_diversity`."""
    data = analyse(log)
    col = data["collision"]
    keep = (
        "agent_pairs",
        "with_static",
        "without_overlap",
        "share_both_below_first_edge",
        "share_one_below_first_edge",
        "pair_share_both_below_first_edge",
        "first_edge",
    )
    return {
        "offroad_events": len(log.offroad_c),
        "collision": {k: col[k] for k in keep},
        "lateral_samples": len(log.lat_offset),
        "offroad_exposure": float(np.sum(log.offroad_exposure)),
        "pair_exposure": float(np.sum(log.pair_exposure)),
    }
