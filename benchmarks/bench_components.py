"""Cost of reward terms as components (issue #13; docs/benchmarks.md "Reward components").

Two measurements, both alternated within one run so that drift of a shared machine hits every
variant alike:

overhead   The paper configuration stepped by this tree and by a baseline tree (another build
           of selfplaydrive, e.g. the commit before the components), in alternating child
           processes: agent-steps per CPU-second and per wall-clock second of each, their
           ratio, and the median per-step time of the whole step and of the reward stage
           alone (a second run with `profile=True`). The baseline tree is a folder holding a
           built `selfplaydrive` package:
               git worktree add /tmp/base <commit> && cd /tmp/base && \
                   python setup.py build_ext --inplace -j 2
terms      The cost of one extra term column in each form: a built-in term of similar work (the
           paper's off-road term again), the speed-limit term of examples 06-08 as numba cfunc,
           as Cython package (built into a temporary folder), and in Python/NumPy. Compiled
           terms are timed in the reward stage (`VecEnv(profile=True)`), the Python term in the
           whole step; cost = time with the term - time without, per agent-step (medians of
           per-step times, then of rounds).

encoders   The observation stage per agent-step of each observation encoder (paper, partial
           observability off / occlusion / every effect, the ego + nearest-objects encoder of
           example 09 as numba cfunc and Cython package), `VecEnv(profile=True)`, alternated.
rules      The traffic-rule encoder (obs=rules) against the paper's, alternated: on the bundled
           town as shipped (118 of its 304 stop lines STOP lines, since the procedural towns
           have them; before, all YIELD) and with every other stop line made a STOP line.

Usage:
    python benchmarks/bench_components.py overhead --baseline /tmp/base [--rounds 6] [--stage physics]
        [--json]
    python benchmarks/bench_components.py terms [--rounds 5] [--json]
    python benchmarks/bench_components.py encoders [--rounds 5] [--json]
    python benchmarks/bench_components.py rules [--rounds 5] [--json]
Run pinned (taskset -c 0) on an otherwise idle machine; both default to one thread.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
# measure this tree's package (built in place), whatever selfplaydrive is installed
sys.path.insert(0, str(ROOT))

# the child of `overhead`: only APIs that every version of the package has
CHILD = r"""
import json, sys, time
import numpy as np
from selfplaydrive.maps.loader import load_map
from selfplaydrive.scenario.spawner import PaperSpawner
from selfplaydrive.sim.vec_env import VecEnv
worlds, threads, steps, warmup = (int(a) for a in sys.argv[1:5])
stage_name = sys.argv[5] if len(sys.argv) > 5 else "reward"
env = VecEnv(load_map("default"), PaperSpawner(), worlds, seed=0, num_threads=threads)
acts = np.random.default_rng(0).integers(0, [7, 13], size=(steps + warmup, env.num_agents, 2))
env.reset(0)
for k in range(warmup):
    env.step(acts[k])
n, per_step = 0, []
c0, t0 = time.process_time(), time.perf_counter()
for k in range(warmup, warmup + steps):
    m = int(np.count_nonzero(env.masks))
    n += m
    s0 = time.perf_counter()
    env.step(acts[k])
    per_step.append((time.perf_counter() - s0) / m * 1e9)
wall, cpu = time.perf_counter() - t0, time.process_time() - c0
# the reward stage alone: profile mode times each stage in its own parallel loop
env = VecEnv(load_map("default"), PaperSpawner(), worlds, seed=0, num_threads=threads, profile=True)
env.reset(0)
for k in range(warmup):
    env.step(acts[k])
stage, obs_stage = [], []
for k in range(warmup, warmup + steps):
    m = int(np.count_nonzero(env.masks))
    r0, o0 = env.timings[stage_name], env.timings["observation"]
    env.step(acts[k])
    stage.append((env.timings[stage_name] - r0) / m * 1e9)
    obs_stage.append((env.timings["observation"] - o0) / m * 1e9)
import selfplaydrive
print(json.dumps({"agent_steps": n, "wall": wall, "cpu": cpu, "median_step_ns": float(np.median(per_step)),
                  "median_reward_stage_ns": float(np.median(stage)),
                  "median_observation_stage_ns": float(np.median(obs_stage)),
                  "package": selfplaydrive.__file__}))
"""


def _child(tree: Path, args: argparse.Namespace) -> dict[str, float]:
    env = dict(os.environ, PYTHONPATH=str(tree))
    cmd = [
        sys.executable,
        "-c",
        CHILD,
        str(args.worlds),
        str(args.threads),
        str(args.steps),
        str(args.warmup),
        args.stage,
    ]
    with tempfile.TemporaryDirectory() as tmp:  # no source tree in the working directory
        out = subprocess.run(cmd, cwd=tmp, env=env, capture_output=True, text=True, check=True).stdout
    r = json.loads(out.strip().splitlines()[-1])
    if not str(r["package"]).startswith(str(tree)):
        raise RuntimeError(f"the child imported {r['package']}, not the package of {tree}")
    return r


def overhead(args: argparse.Namespace) -> dict[str, object]:
    """This tree vs `args.baseline`, alternating child processes."""
    trees = {"baseline": Path(args.baseline).resolve(), "components": ROOT}
    runs: dict[str, list[dict[str, float]]] = {k: [] for k in trees}
    for r in range(args.rounds):
        order = list(trees) if r % 2 == 0 else list(trees)[::-1]  # ABBA: no first-mover bias
        for name in order:
            runs[name].append(_child(trees[name], args))
    out: dict[str, object] = {"worlds": args.worlds, "threads": args.threads, "steps": args.steps}
    for name, rs in runs.items():
        out[name] = {
            "agent_steps_per_cpu_s": statistics.median(x["agent_steps"] / x["cpu"] for x in rs),
            "agent_steps_per_s": statistics.median(x["agent_steps"] / x["wall"] for x in rs),
            "median_step_ns_per_agent": statistics.median(x["median_step_ns"] for x in rs),
            # the stage chosen by --stage (the key keeps its name: reward is the default)
            "median_reward_stage_ns_per_agent": statistics.median(x["median_reward_stage_ns"] for x in rs),
            "median_observation_stage_ns_per_agent": statistics.median(
                x["median_observation_stage_ns"] for x in rs
            ),
            "stage": args.stage,
        }
    pairs = zip(runs["baseline"], runs["components"], strict=True)
    ratios = [(b["agent_steps"] / b["cpu"]) / (c["agent_steps"] / c["cpu"]) for b, c in pairs]
    out["cpu_time_ratio_per_round"] = ratios  # components' CPU time per agent-step / baseline's
    out["cpu_time_ratio_median"] = statistics.median(ratios)
    # medians of per-step wall times (robust to other processes on a shared machine)
    out["median_step_ratio"] = (
        out["components"]["median_step_ns_per_agent"] / out["baseline"]["median_step_ns_per_agent"]
    )
    return out


def _variants() -> dict[str, object]:
    """Extra term of each form (None: the paper's eight only)."""
    sys.path.insert(0, str(ROOT / "examples"))
    from selfplaydrive.rewards import get_term
    from selfplaydrive.testing.build import build_component_package

    variants: dict[str, object] = {"none": None, "builtin": get_term("offroad").renamed("offroad2")}
    try:
        import importlib.util

        spec = importlib.util.spec_from_file_location("example_07", ROOT / "examples" / "07_term_numba.py")
        module = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
        spec.loader.exec_module(module)  # type: ignore[union-attr]
        variants["numba"] = module.speed_limit_term(0.01, 6.0)
    except ImportError as exc:
        print(f"numba form skipped: {exc}", file=sys.stderr)
    target = Path(tempfile.mkdtemp(prefix="bench_components_"))
    build_component_package(ROOT / "examples" / "speed_limit_cython", target)
    sys.path.insert(0, str(target))
    from speed_limit_term import speed_limit_term  # type: ignore[import-not-found]

    variants["cython"] = speed_limit_term(0.01, 6.0)
    spec = importlib.util.spec_from_file_location("example_06", ROOT / "examples" / "06_term_python.py")
    module = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    spec.loader.exec_module(module)  # type: ignore[union-attr]
    variants["python"] = module.SpeedLimit(0.01, 6.0)
    return variants


def _median_stage_ns(env, stage_name: str, args: argparse.Namespace) -> tuple[float, float]:
    """(`stage_name` stage ns, whole-step ns) per agent-step of a profiling `env`: medians of
    per-step times, robust to other processes taking the core now and then."""
    acts = np.random.default_rng(0).integers(0, [7, 13], size=(args.steps + args.warmup, env.num_agents, 2))
    env.reset(0)
    for k in range(args.warmup):
        env.step(acts[k])
    stage, step = [], []
    for k in range(args.warmup, args.warmup + args.steps):
        n = int(np.count_nonzero(env.masks))
        s0, t0 = env.timings[stage_name], time.perf_counter()
        env.step(acts[k])
        step.append((time.perf_counter() - t0) / n * 1e9)
        stage.append((env.timings[stage_name] - s0) / n * 1e9)
    return float(np.median(stage)), float(np.median(step))


def _alternated(variants: dict, time_one, rounds: int, abba: bool = False) -> tuple[dict, dict]:
    """Per variant the lists of (stage, step) times of `time_one(variant)` over `rounds` rounds,
    each round timing every variant once (in reversed order every other round when `abba`)."""
    stage: dict[str, list[float]] = {k: [] for k in variants}
    step: dict[str, list[float]] = {k: [] for k in variants}
    for r in range(rounds):
        order = list(reversed(variants)) if abba and r % 2 else list(variants)
        for name in order:
            s, w = time_one(variants[name])
            stage[name].append(s)
            step[name].append(w)
    return stage, step


def _time_variant(road_map, term, args: argparse.Namespace) -> tuple[float, float]:
    """(reward-stage ns, whole-step ns) per agent-step with `term` added to the paper's terms."""
    from selfplaydrive.rewards import TERM_NAMES, LinearReward
    from selfplaydrive.scenario.spawner import PaperSpawner
    from selfplaydrive.sim.vec_env import VecEnv

    weights = {n: 1.0 for n in TERM_NAMES}
    reward = (
        LinearReward(weights) if term is None else LinearReward({**weights, term.name: 1.0}, terms=[term])
    )
    env = VecEnv(
        road_map, PaperSpawner(), args.worlds, seed=0, num_threads=args.threads, reward=reward, profile=True
    )
    return _median_stage_ns(env, "reward", args)


def terms(args: argparse.Namespace) -> dict[str, object]:
    """Cost of one extra column per form, alternated over `args.rounds` rounds."""
    from selfplaydrive.maps.loader import load_map

    road_map = load_map("default")
    variants = _variants()
    stage, step = _alternated(variants, lambda term: _time_variant(road_map, term, args), args.rounds)
    med = {k: (statistics.median(stage[k]), statistics.median(step[k])) for k in variants}
    out: dict[str, object] = {"worlds": args.worlds, "threads": args.threads, "steps": args.steps}
    base_stage, base_step = med["none"]
    builtin = med["builtin"][0] - base_stage
    for name, (s, w) in med.items():
        row = {"reward_stage_ns": s, "step_ns": w}
        if name != "none":
            # compiled terms run in the reward stage; the Python term after the kernels
            cost = (w - base_step) if name == "python" else (s - base_stage)
            row["term_cost_ns"] = cost
            row["cost_vs_builtin"] = cost / builtin if builtin > 0 else float("nan")
        out[name] = row
    return out


def _encoder_variants() -> dict[str, object]:
    """Observation encoders of each form (issue #13; docs/components.md "Write an observation
    encoder"): the paper's, the partial-observability encoder off / occlusion / every effect,
    and the ego + nearest-objects encoder of example 09 as numba cfunc and Cython package."""
    from selfplaydrive.obs import PaperEncoder, PartialObsEncoder
    from selfplaydrive.testing.build import build_component_package

    variants: dict[str, object] = {
        "paper": PaperEncoder(),
        "partial_off": PartialObsEncoder(),
        "partial_occlusion": PartialObsEncoder(occlusion=True),
        "partial_all": PartialObsEncoder(
            occlusion=True, pos_std=0.5, heading_std=0.05, speed_std=0.3, p_miss=0.05, fp_rate=0.5
        ),
    }
    try:
        import importlib.util

        spec = importlib.util.spec_from_file_location("example_09", ROOT / "examples" / "09_encoder_numba.py")
        module = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
        sys.modules["example_09"] = module
        spec.loader.exec_module(module)  # type: ignore[union-attr]
        variants["ego_objects_numba"] = module.ego_objects_encoder(63, 100.0)
    except ImportError as exc:
        print(f"numba form skipped: {exc}", file=sys.stderr)
    target = Path(tempfile.mkdtemp(prefix="bench_encoders_"))
    build_component_package(ROOT / "examples" / "ego_objects_cython", target)
    sys.path.insert(0, str(target))
    from ego_objects_encoder import ego_objects_encoder  # type: ignore[import-not-found]

    variants["ego_objects_cython"] = ego_objects_encoder(63, 100.0)
    return variants


def _time_encoder(road_map, encoder, args: argparse.Namespace) -> tuple[float, float]:
    """(observation-stage ns, whole-step ns) per agent-step with `encoder`."""
    from selfplaydrive.scenario.spawner import PaperSpawner
    from selfplaydrive.sim.vec_env import VecEnv

    env = VecEnv(
        road_map, PaperSpawner(), args.worlds, seed=0, num_threads=args.threads, obs=encoder, profile=True
    )
    return _median_stage_ns(env, "observation", args)


def encoders(args: argparse.Namespace) -> dict[str, object]:
    """Observation-stage cost per agent-step of each encoder, alternated over `args.rounds`."""
    from selfplaydrive.maps.loader import load_map

    road_map = load_map("default")
    variants = _encoder_variants()
    stage, step = _alternated(variants, lambda enc: _time_encoder(road_map, enc, args), args.rounds)
    out: dict[str, object] = {"worlds": args.worlds, "threads": args.threads, "steps": args.steps}
    base = statistics.median(stage["paper"])
    for name in variants:
        s = statistics.median(stage[name])
        out[name] = {
            "observation_stage_ns": s,
            "step_ns": statistics.median(step[name]),
            "vs_paper": s / base,
        }
    return out


def rules(args: argparse.Namespace) -> dict[str, object]:
    """Observation stage and whole step per agent-step of `RulesEncoder` vs `PaperEncoder`,
    alternated over `args.rounds` (paper, rules, rules on the town with STOP lines, paper on it)."""
    import dataclasses

    from selfplaydrive.maps.loader import load_map
    from selfplaydrive.obs import PaperEncoder, RulesEncoder

    town = load_map("default")
    kinds = np.zeros(len(town.stop_kind), np.int8)
    kinds[1::2] = 1  # StopKind.YIELD; the even ones STOP
    stops = dataclasses.replace(town, stop_kind=kinds)
    variants = {
        "paper": (town, PaperEncoder()),
        "rules": (town, RulesEncoder()),
        "paper_stop_town": (stops, PaperEncoder()),
        "rules_stop_town": (stops, RulesEncoder()),
    }
    stage, step = _alternated(variants, lambda v: _time_encoder(*v, args), args.rounds, abba=True)
    out: dict[str, object] = {"worlds": args.worlds, "threads": args.threads, "steps": args.steps}
    for name in variants:
        base = "paper_stop_town" if name.endswith("stop_town") else "paper"
        out[name] = {
            "observation_stage_ns": statistics.median(stage[name]),
            "step_ns": statistics.median(step[name]),
            "stage_vs_paper_per_round": [a / b for a, b in zip(stage[name], stage[base], strict=True)],
            "step_vs_paper_per_round": [a / b for a, b in zip(step[name], step[base], strict=True)],
        }
    return out


def _print(title: str, result: dict[str, object], as_json: bool) -> None:
    if as_json:
        print(json.dumps(result, indent=1))
        return
    print(title)
    for k, v in result.items():
        print(f"  {k}: {v}")


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("what", choices=("overhead", "terms", "encoders", "rules"))
    p.add_argument("--baseline", help="folder holding the baseline's built selfplaydrive package (overhead)")
    p.add_argument("--worlds", type=int, default=32, help="worlds (32 agent slots each)")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--steps", type=int, default=300, help="timed steps per run")
    p.add_argument("--warmup", type=int, default=30)
    p.add_argument("--rounds", type=int, default=6, help="alternations")
    p.add_argument(
        "--stage",
        default="reward",
        choices=("physics", "events", "reward", "observation", "finalize"),
        help="stage timed alone in the overhead's profile run (physics: the physics components' cost)",
    )
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    if args.what == "overhead":
        if not args.baseline:
            p.error("overhead needs --baseline")
        _print("overhead (paper configuration, this tree vs baseline)", overhead(args), args.json)
    elif args.what == "encoders":
        _print("observation stage per encoder", encoders(args), args.json)
    elif args.what == "rules":
        _print("obs=rules vs obs=paper (per agent-step)", rules(args), args.json)
    else:
        _print("cost of one extra reward column per form", terms(args), args.json)


if __name__ == "__main__":
    main()
