"""PPO training throughput: agent-steps/s of whole updates (collection + learning), of
collection alone, per CPU-second, and the share of time per phase, for any train config;
optionally alternated with an earlier build of the trainer and models in the same run
(docs/benchmarks.md, "Trainer").

    python benchmarks/bench_train.py                                  # the main job's settings
    python benchmarks/bench_train.py '~experiment' trainer.torch_threads=1   # paper-size Deep Sets
    python benchmarks/bench_train.py --baseline HEAD~1 --updates 6    # this tree vs HEAD~1
    python benchmarks/bench_train.py --json trainer.torch_threads=2 env.num_threads=2
    python benchmarks/bench_train.py trainer.torch_threads=2 --baseline-overrides trainer.torch_threads=1
    python benchmarks/bench_train.py trainer.torch_threads=2 --baseline-env OMP_WAIT_POLICY=passive
    python benchmarks/bench_train.py --baseline HEAD~1 --init-from pretrained <its env overrides>

(Hydra overrides first: `--baseline-overrides` / `--baseline-env` take every word after them.)

Every build runs in its own worker process: one warm-up update (allocations, first reset), then
one update per request. With `--baseline REV` the worker of the baseline imports
`selfplaydrive/models` and `selfplaydrive/trainers/ppo` from `git archive REV` (everything else,
the simulator included, is this tree's), and the two workers take turns update by update, the
order flipping every round, so both see the same machine load. Reported per build: medians
over the counted updates of active agent-steps/s (wall), agent-steps per CPU-second of the
worker (`time.process_time`, all its threads), collection-only agent-steps/s, and the share
of wall time in env.step, policy inference (the rest of collection), advantages (GAE) and the
PPO epochs; with a baseline, the ratio of the medians and the median of the per-round ratios.

Agent-steps count the slots that act, and a build whose update skips the others costs less per
update when fewer act; two builds that learn from the same start soon drive differently and
keep different numbers of agents alive (a policy that learns to stand keeps them all). So
slot-steps/s, the acting share and the acting agents' mean speed are reported too, and
`--init-from` starts both builds from the same weights (a checkpoint, "pretrained", or
"initial": this tree's initial weights for the overrides); with `trainer.learning_rate=1e-12`
both then act with the same policy throughout: the same work for both, the trainer's speed
alone (docs/benchmarks.md, "Trainer").
"""

from __future__ import annotations

import argparse
import importlib.abc
import importlib.util
import io
import json
import os
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
# The packages a baseline replaces; the rest of selfplaydrive (env, builder, configs) is shared.
OVERLAID = ("selfplaydrive.models", "selfplaydrive.trainers.ppo")
PHASES = ("env_step", "policy", "advantages", "update")


class _Overlay(importlib.abc.MetaPathFinder):
    """Finds the `OVERLAID` packages (and their modules) under `root` instead of this tree."""

    def __init__(self, root: Path) -> None:
        self.root = root

    def find_spec(self, name: str, path: object = None, target: object = None):
        if not any(name == pkg or name.startswith(pkg + ".") for pkg in OVERLAID):
            return None
        location = self.root.joinpath(*name.split("."))
        if location.is_dir():
            init = location / "__init__.py"
            return importlib.util.spec_from_file_location(
                name, init, submodule_search_locations=[str(location)]
            )
        file = location.with_suffix(".py")
        return importlib.util.spec_from_file_location(name, file) if file.exists() else None


def export_build(rev: str, dest: Path) -> None:
    """Write the `OVERLAID` packages of git revision `rev` under `dest`."""
    paths = [pkg.replace(".", "/") for pkg in OVERLAID]
    tar = subprocess.run(
        ["git", "-C", str(REPO), "archive", "--format=tar", rev, *paths], check=True, capture_output=True
    ).stdout
    with tarfile.open(fileobj=io.BytesIO(tar)) as archive:
        archive.extractall(dest, filter="data")


# ---------------------------------------------------------------------------------------------
# worker: builds one trainer and answers "update" lines with one JSON line each


def build_trainer(overrides: list[str], seed_everything):
    """The trainer `selfplaydrive train <overrides>` would build (seeded, no run folder);
    `seed_everything` is `selfplaydrive.trainers.run.seed_everything`."""
    from dataclasses import fields

    from omegaconf import OmegaConf

    from selfplaydrive.builder import build_env, build_model, compose
    from selfplaydrive.trainers.ppo.config import PPOConfig
    from selfplaydrive.trainers.ppo.trainer import PPOTrainer

    cfg = compose("train", overrides)
    values = OmegaConf.to_container(cfg.trainer, resolve=True)
    known = {f.name for f in fields(PPOConfig)}  # a baseline may predate some keys
    values = {k: v for k, v in values.items() if k in known}
    values.update(progress_bar=False, checkpoint_interval=0, total_steps=10**12)
    config = PPOConfig(**values)
    seed_everything(int(cfg.seed), config.torch_threads)
    env = build_env(cfg)
    model = build_model(cfg, env)
    return PPOTrainer(env, model, config, None), cfg


def timed_env_step(env) -> list[float]:
    """Wrap `env.step` so that its wall time adds up in the returned one-element list."""
    total = [0.0]
    step = env.step

    def wrapper(actions):
        t0 = time.perf_counter()
        step(actions)
        total[0] += time.perf_counter() - t0

    env.step = wrapper
    return total


def acting_speed(env) -> float:
    """Mean speed [m/s] of the agents acting now (0 when none act). The env is this tree's in
    every build, so the figure compares the builds' policies: one that learns to stand keeps its
    agents alive, and more agent-steps per slot-step, without a faster trainer."""
    import numpy as np

    acting = env.masks
    return float(np.mean(env.buffers["speed"].reshape(-1)[acting])) if acting.any() else 0.0


def one_overlapped_update(trainer, env_time: list[float]) -> dict[str, float]:
    """One update with `trainer.overlap_collection` (the next rollout collected in a second
    thread meanwhile): phases overlap, so `update` is the wall time and `collect_s` the
    collector thread's own."""
    steps0, env0 = trainer.agent_steps, env_time[0]
    cpu0, t0 = time.process_time(), time.perf_counter()
    metrics = trainer.train(num_updates=1)
    t1, cpu1 = time.perf_counter(), time.process_time()
    steps = trainer.agent_steps - steps0
    collect_s = steps / metrics["collect_sps"] if metrics.get("collect_sps") else float("nan")
    env_s = env_time[0] - env0
    return {
        "acting_speed": acting_speed(trainer.env),
        "agent_steps": steps,
        "wall_s": t1 - t0,
        "cpu_s": cpu1 - cpu0,
        "collect_s": collect_s,
        "env_step": env_s,
        "policy": collect_s - env_s,
        "advantages": 0.0,
        "update": t1 - t0,
    }


def one_update(trainer, env_time: list[float]) -> dict[str, float]:
    """Run one PPO update; its agent-steps, wall and CPU seconds per phase."""
    import torch

    if getattr(trainer, "overlap", False):
        return one_overlapped_update(trainer, env_time)

    # device work is asynchronous: wait for it at each phase's end (a no-op on the CPU)
    sync = torch.cuda.synchronize if trainer.device.type == "cuda" else (lambda: None)
    sync()
    steps0, env0 = trainer.agent_steps, env_time[0]
    cpu0, t0 = time.process_time(), time.perf_counter()
    trainer.collect()
    sync()
    t1 = time.perf_counter()
    trainer.compute_advantages()
    sync()
    t2 = time.perf_counter()
    trainer.update()
    trainer.update_idx += 1
    sync()
    t3, cpu1 = time.perf_counter(), time.process_time()
    if trainer.device.type == "cuda":  # hand the update's peak memory to the other worker
        torch.cuda.empty_cache()
    env_s = env_time[0] - env0
    return {
        "acting_speed": acting_speed(trainer.env),
        "agent_steps": trainer.agent_steps - steps0,
        "wall_s": t3 - t0,
        "cpu_s": cpu1 - cpu0,
        "collect_s": t1 - t0,
        "env_step": env_s,
        "policy": t1 - t0 - env_s,
        "advantages": t2 - t1,
        "update": t3 - t2,
    }


def install_overlay(overlay: str | None):
    """Make the `OVERLAID` packages come from `overlay` (None: this tree's); returns this
    tree's `seed_everything`.

    This tree's `trainers/run.py` imports names an older trainer package may lack, so it is
    imported before the overlay goes in, and the overlaid packages it pulled in are then
    forgotten: the trainer and model imported afterwards come from `overlay`."""
    from selfplaydrive.trainers.run import seed_everything

    if overlay:
        for name in [m for m in sys.modules if any(m == p or m.startswith(p + ".") for p in OVERLAID)]:
            del sys.modules[name]
        sys.meta_path.insert(0, _Overlay(Path(overlay)))
    return seed_everything


def weights_digest(state: dict) -> str:
    """Short SHA-256 of a model's weights (names and values in order): equal digests, equal
    starting weights."""
    import hashlib

    h = hashlib.sha256()
    for name, value in state.items():
        h.update(name.encode())
        h.update(value.detach().cpu().contiguous().numpy().tobytes())
    return h.hexdigest()[:16]


def worker(
    overrides: list[str], overlay: str | None, init_from: str | None = None, save_initial: str | None = None
) -> None:
    """Build, warm up, print a JSON info line, then one JSON line per "update" on stdin.
    `init_from`: load these weights first (read by this tree's checkpoint code, whichever
    build runs: an older build may not read the checkpoint's format). `save_initial`: write
    the starting weights there (this tree's checkpoint format) before the warm-up."""
    weights = None
    if init_from:
        from selfplaydrive.policies import load_checkpoint
        from selfplaydrive.pretrained import resolve_spec

        weights = load_checkpoint(resolve_spec(init_from))["model"]
    seed_everything = install_overlay(overlay)
    import torch

    trainer, cfg = build_trainer(overrides, seed_everything)
    if weights is not None:
        trainer.model.load_state_dict(dict(weights))
        actor = getattr(trainer, "actor", trainer.model)  # overlap_collection's copy
        if actor is not trainer.model:
            actor.load_state_dict(trainer.model.state_dict())
    start = weights_digest(trainer.model.state_dict())
    if save_initial:
        from selfplaydrive.trainers.ppo import checkpoint

        checkpoint.save(save_initial, {"model": trainer.model.state_dict()})
    env_time = timed_env_step(trainer.env)
    t0 = time.perf_counter()
    trainer.train(num_updates=1)  # warm-up: allocations, first reset, compiling (trainer.compile)
    if trainer.device.type == "cuda":  # a second worker starts next on the same GPU
        torch.cuda.empty_cache()
    info = {
        "warmup_s": time.perf_counter() - t0,
        "model": type(trainer.model).__name__,
        "parameters": sum(p.numel() for p in trainer.model.parameters()),
        "obs_dim": trainer.env.layout.obs_dim,
        "agent_slots": trainer.env.num_agents,
        "rollout_length": trainer.config.rollout_length,
        "torch_threads": torch.get_num_threads(),
        "env_threads": int(cfg.env.num_threads),
        "device": str(trainer.device),
        "gpu": torch.cuda.get_device_name(trainer.device) if trainer.device.type == "cuda" else None,
        "precision": str(getattr(trainer, "amp_dtype", None) or "fp32"),
        "staged_uploads": sorted(getattr(trainer._to_device, "failed", {})),
        "trainer_file": sys.modules[type(trainer).__module__].__file__,
        "slots_per_update": trainer.slots_per_update,
        "init_from": init_from,
        "initial_weights": start,
    }
    print(json.dumps(info), flush=True)
    for line in sys.stdin:
        if line.strip() != "update":
            break
        print(json.dumps(one_update(trainer, env_time)), flush=True)


# ---------------------------------------------------------------------------------------------
# parent: starts the workers, alternates them, summarises


class Worker:
    """A worker process of one build (`overlay`: the baseline's exported tree, or None)."""

    def __init__(
        self,
        label: str,
        overrides: list[str],
        overlay: Path | None,
        env: dict[str, str] | None = None,
        init_from: str | None = None,
        save_initial: str | None = None,
    ) -> None:
        cmd = [sys.executable, __file__, "--worker", *(["--overlay", str(overlay)] if overlay else [])]
        cmd += ["--init-from", init_from] if init_from else []
        cmd += ["--save-initial", save_initial] if save_initial else []
        self.label = label
        self.proc = subprocess.Popen(
            [*cmd, "--", *overrides],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            cwd=REPO,
            env={**os.environ, **(env or {})},
        )
        self.info = self._read()
        self.updates: list[dict[str, float]] = []

    def _read(self) -> dict[str, object]:
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError(f"{self.label} worker exited (rc {self.proc.wait()}); see its stderr above")
        return json.loads(line)

    def update(self) -> dict[str, float]:
        self.proc.stdin.write("update\n")
        self.proc.stdin.flush()
        result = self._read()
        self.updates.append(result)
        print(
            f"  {self.label}: {rate(result):,.0f} agent-steps/s "
            f"({result['agent_steps']} in {result['wall_s']:.2f} s)",
            flush=True,
        )
        return result

    def close(self) -> None:
        self.proc.stdin.close()
        self.proc.wait()


def rate(u: dict[str, float]) -> float:
    return u["agent_steps"] / u["wall_s"]


def summarize(updates: list[dict[str, float]], slots: int) -> dict[str, float]:
    """Medians over updates: agent-steps/s (wall, CPU, collection), slot-steps/s (`slots`
    slot-steps an update), the acting share, the acting agents' speed and the phase shares."""
    med = statistics.median
    out = {
        "agent_steps_per_s": med(rate(u) for u in updates),
        "slot_steps_per_s": med(slots / u["wall_s"] for u in updates),
        "acting_share": med(u["agent_steps"] / slots for u in updates),
        "acting_speed": med(u["acting_speed"] for u in updates),
        "agent_steps_per_cpu_s": med(u["agent_steps"] / u["cpu_s"] for u in updates),
        "collect_agent_steps_per_s": med(u["agent_steps"] / u["collect_s"] for u in updates),
        "wall_s_per_update": med(u["wall_s"] for u in updates),
    }
    for phase in PHASES:
        out[f"share_{phase}"] = med(u[phase] / u["wall_s"] for u in updates)
    return out


def run(
    overrides: list[str],
    updates: int,
    baseline: str | None,
    baseline_overrides: list[str] = (),
    baseline_env: dict[str, str] | None = None,
    init_from: str | None = None,
) -> dict[str, object]:
    """Alternate the workers for `updates` rounds; returns the summary.

    A baseline worker runs when `baseline` (a git revision) or `baseline_overrides` /
    `baseline_env` (extra Hydra overrides / environment variables of the baseline worker, to
    compare settings of one build) are given; without a revision it runs this tree."""
    load0 = os.getloadavg()
    compare = bool(baseline or baseline_overrides or baseline_env)
    if init_from and init_from not in ("pretrained", "initial"):
        init_from = str(Path(init_from).resolve())  # the workers run in the repository root
    with tempfile.TemporaryDirectory(prefix="bench_train_") as tmp:
        # "initial": this tree's worker writes its starting weights, the baseline's starts from them
        current_init, initial, baseline_init = init_from, None, init_from
        if init_from == "initial":
            current_init, initial = None, str(Path(tmp) / "initial.pt")
            baseline_init = initial
        workers = [Worker("current", overrides, None, init_from=current_init, save_initial=initial)]
        if baseline:
            export_build(baseline, Path(tmp))
        if compare:
            label = " ".join(["baseline", baseline or "(this tree)", *baseline_overrides])
            overlay = Path(tmp) if baseline else None
            workers.append(
                Worker(label, [*overrides, *baseline_overrides], overlay, baseline_env, baseline_init)
            )
        try:
            for i in range(updates):
                for w in workers if i % 2 == 0 else workers[::-1]:
                    w.update()
        finally:
            for w in workers:
                w.close()
    result: dict[str, object] = {
        "overrides": overrides,
        "updates": updates,
        "load_avg_start": load0[0],
        "load_avg_end": os.getloadavg()[0],
        "cpu_count": os.cpu_count(),
    }
    for w in workers:
        key = "current" if w.label == "current" else "baseline"
        result[key] = {
            **w.info,
            "rev": w.label[len("baseline ") :] if key == "baseline" else "working tree",
            "env": baseline_env if key == "baseline" else {},
            **summarize(w.updates, int(w.info["slots_per_update"])),
        }
    if compare:
        cur, base = workers[0].updates, workers[1].updates
        result["ratio_of_medians"] = (
            result["current"]["agent_steps_per_s"] / result["baseline"]["agent_steps_per_s"]
        )
        result["median_round_ratio"] = statistics.median(
            rate(a) / rate(b) for a, b in zip(cur, base, strict=True)
        )
        result["cpu_ratio_of_medians"] = (
            result["current"]["agent_steps_per_cpu_s"] / result["baseline"]["agent_steps_per_cpu_s"]
        )
        result["slot_ratio_of_medians"] = (
            result["current"]["slot_steps_per_s"] / result["baseline"]["slot_steps_per_s"]
        )
    return result


def report(result: dict[str, object]) -> str:
    """Human-readable lines of `run`'s result."""
    lines = [
        f"load average {result['load_avg_start']:.2f} -> {result['load_avg_end']:.2f} "
        f"on {result['cpu_count']} CPUs"
    ]
    for key in ("current", "baseline"):
        if key not in result:
            continue
        r = result[key]
        build = " ".join([r["rev"], *(f"{k}={v}" for k, v in r.get("env", {}).items())])
        shares = ", ".join(f"{p} {r[f'share_{p}']:.0%}" for p in PHASES)
        lines.append(
            f"{key} ({build}): {r['model']} ({r['parameters']:,} params, obs {r['obs_dim']}), "
            f"{r['agent_slots']} slots, torch threads {r['torch_threads']}, env threads {r['env_threads']}: "
            f"{r['agent_steps_per_s']:,.0f} agent-steps/s overall, "
            f"{r['agent_steps_per_cpu_s']:,.0f} per CPU-s, "
            f"{r['collect_agent_steps_per_s']:,.0f} collecting; {r['slot_steps_per_s']:,.0f} slot-steps/s, "
            f"acting share {r['acting_share']:.0%} at {r['acting_speed']:.1f} m/s; time: {shares}; "
            f"warm-up update {r['warmup_s']:.1f} s"
        )
    if "ratio_of_medians" in result:
        lines.append(
            f"current / baseline: {result['ratio_of_medians']:.2f}x (median of per-round ratios "
            f"{result['median_round_ratio']:.2f}x, per CPU-second {result['cpu_ratio_of_medians']:.2f}x); "
            f"slot-steps/s {result['slot_ratio_of_medians']:.2f}x"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("overrides", nargs="*", help="Hydra overrides of the train config")
    parser.add_argument(
        "--updates", type=int, default=5, help="counted updates per build (after one warm-up)"
    )
    parser.add_argument(
        "--baseline", metavar="REV", help="git revision to alternate with (its models and trainer)"
    )
    parser.add_argument(
        "--baseline-overrides",
        nargs="*",
        default=[],
        metavar="KEY=VALUE",
        help="extra overrides of the baseline",
    )
    parser.add_argument(
        "--baseline-env",
        nargs="*",
        default=[],
        metavar="NAME=VALUE",
        help="environment of the baseline worker",
    )
    parser.add_argument(
        "--init-from",
        metavar="CKPT",
        help='start every build from these weights (a checkpoint, "pretrained", or "initial": this '
        "tree's initial weights for the overrides); with trainer.learning_rate=1e-12 both act with "
        "the same policy throughout",
    )
    parser.add_argument("--json", action="store_true", help="print the summary as JSON")
    parser.add_argument("--json-out", metavar="FILE", help="also write the summary as JSON to FILE")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--overlay", help=argparse.SUPPRESS)
    parser.add_argument("--save-initial", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        worker(args.overrides, args.overlay, args.init_from, args.save_initial)
        return
    env = dict(item.split("=", 1) for item in args.baseline_env)
    result = run(args.overrides, args.updates, args.baseline, args.baseline_overrides, env, args.init_from)
    print(json.dumps(result) if args.json else report(result))
    if args.json_out:
        Path(args.json_out).write_text(json.dumps(result, indent=1) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
