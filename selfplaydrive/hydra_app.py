"""Hydra entry points of the CLI: `selfplaydrive train|eval|render|bench` take Hydra overrides
and `-m` multirun. Each run folder gets the resolved config, the git commit and the seed.
"""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from selfplaydrive.builder import CONFIG_MODULE, compose
from selfplaydrive.errors import CheckpointError, ConfigError, MapError, MissingExtraError

# run-folder helpers live in runs.py (eval/app.py and the trainers use them too); the names
# stay importable from here
from selfplaydrive.runs import git_commit as git_commit
from selfplaydrive.runs import write_run_meta

# Hydra's own command-line flags (hydra/_internal/utils.py get_args_parser)
HYDRA_FLAGS = {
    "-m", "--multirun", "--cfg", "-c", "--resolve", "--info", "-i", "--help", "-h", "--hydra-help",
    "--version", "--package", "-p", "--run", "-r", "--shell-completion", "-sc", "--config-path",
    "-cp", "--config-name", "-cn", "--config-dir", "-cd", "--experimental-rerun",
}  # fmt: skip


# bench.yaml keys that must be integers, with their smallest value
BENCH_COUNTS = {"steps": 1, "warmup": 0, "repeats": 1}


def full_error() -> bool:
    """Whether the user asked for full tracebacks (Hydra's HYDRA_FULL_ERROR=1)."""
    return os.environ.get("HYDRA_FULL_ERROR") == "1"


def one_line_errors() -> tuple[type[BaseException], ...]:
    """Exceptions that are the user's input, not a bug: reported in one line, no traceback.

    Our own errors, a missing optional dependency, and OmegaConf's and Hydra's errors on a bad
    override value (a string where an int belongs, a missing mandatory value ...).
    """
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    return (ConfigError, MapError, CheckpointError, MissingExtraError, OmegaConfBaseException, HydraException)


def one_line(exc: BaseException) -> str:
    """The message of `exc` for the one-line report: OmegaConf's multi-line messages become
    'key: first line' (their other lines repeat the key and the node type), Hydra's are joined
    into one line; ours are kept (a ConfigError may list the valid choices below)."""
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    msg = str(exc).strip() or type(exc).__name__
    if isinstance(exc, OmegaConfBaseException):
        first = msg.splitlines()[0]
        key = getattr(exc, "full_key", None)
        return f"{key}: {first}" if key and not first.startswith(f"{key}:") else first
    if isinstance(exc, HydraException):  # e.g. a parse error, then a line with the grammar's URL
        return " ".join(line.strip() for line in msg.splitlines() if line.strip())
    return msg


def check_config(config_name: str, cfg: Any) -> None:
    """Cheap checks of the values every command reads, so that a bad one fails in a line before
    a map is loaded or a run folder is written.

    Raises:
        ConfigError: Naming the key, the value and what was expected.
    """
    from omegaconf import OmegaConf

    from selfplaydrive.sim.vec_env import MAX_THREADS, check_integer, check_seed

    if "seed" in cfg:
        check_seed(cfg.seed)
    if "env" in cfg:
        check_integer("env.num_worlds", cfg.env.num_worlds, 1)
        check_integer("env.num_threads", cfg.env.num_threads, 1, MAX_THREADS)
    if "map" in cfg:
        nodes = list(cfg.map) if OmegaConf.is_list(cfg.map) else [cfg.map]
        for node in nodes:
            # `"spec" in node` is False for a missing value: ask the keys
            if OmegaConf.is_dict(node) and "spec" in node.keys() and OmegaConf.is_missing(node, "spec"):
                raise ConfigError(
                    "map.spec: map=file needs the map file, e.g. map=file map.spec=path/to/map.osm "
                    "(.osm Lanelet2, .xodr OpenDRIVE or a compiled .npz)"
                )
    if config_name == "bench":
        for key, low in BENCH_COUNTS.items():
            check_integer(key, cfg[key], low)
        threads = list(cfg.threads) if OmegaConf.is_list(cfg.threads) else [cfg.threads]
        for t in threads:
            check_integer("threads", t, 1, MAX_THREADS)


def check_overrides(config_name: str, argv: Sequence[str]) -> None:
    """Compose once with the first value of every sweep so that an unknown group option or key
    fails before any run starts, with a `ConfigError` listing the valid choices; then check the
    values (`check_config`)."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    overrides = [a for a in argv if not a.startswith("-") and "=" in a]
    first = []
    for ov in OverridesParser.create().parse_overrides(overrides):
        key = ov.get_key_element()
        if ov.is_sweep_override():
            value = next(iter(ov.sweep_string_iterator()))
        else:
            value = ov.get_value_element_as_str()
        first.append(f"{key}={value}")
    check_config(config_name, compose(config_name, first))


def run_hydra(
    config_name: str,
    task: Callable[[Any], Any],
    argv: Sequence[str],
    usage_errors: tuple[type[Exception], ...] = (),
) -> int:
    """Run `task(cfg)` under Hydra with `argv` as the override list (supports `-m`).

    Returns:
        The exit code: 0 when every run succeeded, 1 when a run raised a `ConfigError`,
        `MapError`, `CheckpointError`, `MissingExtraError` or an OmegaConf / Hydra error on a bad
        value (one line on stderr, no traceback; the other runs of a sweep still run), 2 on an
        unknown command-line flag or when a run raised one of `usage_errors`. With
        HYDRA_FULL_ERROR=1 these errors propagate with their full traceback.
    """
    import hydra

    argv = list(argv)
    flags = [a for a in argv if a.startswith("-") and a.split("=", 1)[0] not in HYDRA_FLAGS]
    if flags:
        print(
            f"selfplaydrive {config_name}: error: unrecognized argument(s) {' '.join(flags)}; this command "
            "takes Hydra overrides key=value (see --help, and --cfg job for the keys) and -m for sweeps",
            file=sys.stderr,
        )
        return 2
    user_errors = one_line_errors()
    try:
        check_overrides(config_name, argv)
    except user_errors as exc:
        if full_error():
            raise
        print(f"selfplaydrive {config_name}: error: {one_line(exc)}", file=sys.stderr)
        return 1
    status = [0]

    @hydra.main(config_path=f"pkg://{CONFIG_MODULE}", config_name=config_name, version_base="1.3")
    def _main(cfg: Any) -> Any:
        try:
            check_config(config_name, cfg)  # each job of a sweep, before its task loads anything
            return task(cfg)
        except user_errors as exc:
            code = 1
            error = exc
        except usage_errors as exc:
            code = 2
            error = exc
        if full_error():
            raise error
        print(f"selfplaydrive {config_name}: error: {one_line(error)}", file=sys.stderr)
        status[0] = max(status[0], code)
        return None

    saved = sys.argv
    sys.argv = [f"selfplaydrive {config_name}", *argv]
    try:
        _main()
    finally:
        sys.argv = saved
    return status[0]


def train_task(cfg: Any) -> dict[str, Any]:
    """One training run: build env and model from the config, train, evaluate (torch needed)."""
    from selfplaydrive.builder import build_env, build_model, instantiate
    from selfplaydrive.trainers.run import seed_everything, train_run

    run_dir = write_run_meta(cfg)
    env = build_env(cfg)
    trainer = instantiate(cfg.trainer)
    logger = instantiate(cfg.logger, _partial_=True)  # the trainer fills run_dir, total_updates ...
    if hasattr(trainer, "run"):  # e.g. the stable-baselines3 path (trainer=sb3) builds its own policy
        return trainer.run(env, cfg, run_dir, logger=logger)
    seed_everything(int(cfg.seed), trainer.torch_threads)  # before the model: its initial weights
    model = build_model(cfg, env)
    if cfg.get("init_widen") and cfg.get("init_from") is None:
        raise ConfigError("init_widen=true needs init_from=<narrower checkpoint .pt or pretrained>; got none")
    if cfg.get("init_from") is not None:
        if cfg.get("resume") is not None:
            raise ConfigError(
                "init_from and resume both set; expected one: resume continues a run (its optimiser, "
                "counters and env), init_from starts a new run from a checkpoint's model weights"
            )
        from selfplaydrive.trainers.run import init_weights

        init_weights(model, str(cfg.init_from), widen=bool(cfg.get("init_widen", False)))
    return train_run(env, model, trainer, run_dir, logger=logger, resume=cfg.get("resume"))


def torchrun_run_dir(argv: Sequence[str], environ: Mapping[str, str] | None = None) -> list[str]:
    """Under torchrun, one run folder for every rank: the default folder is a time stamp that
    each process takes from its own clock, so ranks starting in different seconds (other nodes)
    would write to separate folders. Without an explicit `hydra.run.dir`, the folder is named
    by torchrun's run id (`--rdzv-id`, the same on every node)."""
    env = os.environ if environ is None else environ
    run_id = env.get("TORCHELASTIC_RUN_ID")
    if not run_id or int(env.get("WORLD_SIZE", "1")) <= 1:
        return list(argv)
    if any(a.startswith(("hydra.run.dir=", "-m", "--multirun")) for a in argv):
        return list(argv)
    return [*argv, f"hydra.run.dir=outputs/train/torchrun-{run_id}"]


def cmd_train(argv: Sequence[str]) -> int:
    """``selfplaydrive train [overrides] [-m]``. Under torchrun, the process ends here with
    the run's status (`exit_distributed`: a clean exit, not an abort in Gloo's teardown)."""
    status = run_hydra("train", train_task, torchrun_run_dir(argv))
    if "torch.distributed" in sys.modules:  # only a run that trained has torch loaded
        from selfplaydrive.trainers.ppo.dist import exit_distributed

        exit_distributed(status)
    return status


def eval_task(cfg: Any) -> Any:
    """One evaluation run (selfplaydrive/eval/app.py), imported inside the run so that a
    missing optional dependency is reported in one line like any other run error."""
    from selfplaydrive.eval.app import eval_task as run_eval

    return run_eval(cfg)


def cmd_eval(argv: Sequence[str]) -> int:
    """``selfplaydrive eval [overrides] [-m]``."""
    return run_hydra("eval", eval_task, argv)


def render_driver(cfg: Any) -> str:
    """What drives `selfplaydrive render`: `policy` when set (as in `selfplaydrive eval`), else
    `driver`; "pretrained" becomes the shipped checkpoint's path (`selfplaydrive.pretrained`)."""
    from selfplaydrive.pretrained import resolve_spec

    policy = cfg.get("policy")
    return resolve_spec(str(cfg.driver if policy is None else policy))


def checkpoint_env_kwargs(driver: str) -> dict[str, Any]:
    """`VecEnv` arguments of the env a checkpoint was trained in (observation sizes, action
    table, scales, physics: `policies.trained_env_kwargs`), from the run config next to it;
    empty for a built-in driver or a checkpoint without one (the render config's env is used)."""
    from selfplaydrive.policies import find_run_config, is_builtin, load_run_config, trained_env_kwargs

    if is_builtin(driver) or not Path(driver).is_file():
        return {}
    cfg_file = find_run_config(driver)
    return {} if cfg_file is None else trained_env_kwargs(load_run_config(cfg_file))


def render_task(cfg: Any) -> dict[str, Any]:
    """One rendered episode: build the env of the config, drive and draw it (conf/render.yaml)."""
    from selfplaydrive.builder import build_env
    from selfplaydrive.render.video import render_episode

    write_run_meta(cfg)
    driver = render_driver(cfg)
    env = build_env(cfg, **checkpoint_env_kwargs(driver))
    out = render_episode(
        cfg.output,
        driver=driver,
        steps=int(cfg.steps),
        world=int(cfg.world),
        seed=int(cfg.seed),
        fps=float(cfg.fps),
        follow=None if cfg.follow is None else int(cfg.follow),
        size=int(cfg.size),
        view=None if cfg.view is None else float(cfg.view),
        tail=int(cfg.tail),
        every=int(cfg.every),
        waypoints=bool(cfg.waypoints),
        text=bool(cfg.text),
        deterministic=bool(cfg.deterministic),
        env=env,
    )
    files = out["files"]
    where = files[0] if len(files) == 1 else f"{files[0]} ... {files[-1]}"
    print(
        f"wrote {out['frames']} frames to {where} (stepping {out['record_s']:.1f} s, "
        f"drawing and writing {out['render_s']:.1f} s = {out['render_fps']:.1f} frames/s)"
    )
    return out


def bench_task(cfg: Any) -> dict[str, Any]:
    """Simulator throughput of the config's env at each thread count (conf/bench.yaml); prints
    text or, with `json=true`, one JSON object; writes bench.json into the run folder."""
    from omegaconf import OmegaConf

    from selfplaydrive.builder import build_env, build_maps
    from selfplaydrive.sim.bench import _print_text, run_bench

    run_dir = write_run_meta(cfg)
    maps = build_maps(cfg.map)  # loaded once for every thread count

    def make_env(threads: int, profile: bool) -> Any:
        return build_env(cfg, maps=maps, num_threads=threads, profile=profile)

    name = str(cfg.map.spec) if "spec" in cfg.map else maps[0].name
    threads = [int(t) for t in cfg.threads] if OmegaConf.is_list(cfg.threads) else [int(cfg.threads)]
    out = run_bench(
        make_env,
        name,
        threads,
        int(cfg.steps),
        int(cfg.warmup),
        int(cfg.repeats),
        int(cfg.seed),
        bool(cfg.stages),
    )
    (run_dir / "bench.json").write_text(json.dumps(out, indent=2) + "\n")
    if cfg.json:
        print(json.dumps(out))
    else:
        _print_text(out)
    return out


def cmd_render(argv: Sequence[str]) -> int:
    """``selfplaydrive render [overrides] [-m]``; 2 on bad arguments (an unknown output format,
    world or follow out of range, MP4 without the video extra)."""
    return run_hydra("render", render_task, argv, usage_errors=(ValueError, RuntimeError))


def cmd_bench(argv: Sequence[str]) -> int:
    """``selfplaydrive bench [overrides] [json=true] [-m]``; ``--json`` is short for ``json=true``."""
    argv = ["json=true" if a == "--json" else a for a in argv]
    return run_hydra("bench", bench_task, argv, usage_errors=(ValueError,))
