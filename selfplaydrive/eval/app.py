"""`selfplaydrive eval`: run the chosen analyses for a checkpoint, the shipped pretrained policy
(`policy=pretrained`, `selfplaydrive.pretrained`) or a built-in driver and write JSON plus a
markdown table per analysis into the run folder (paper section 5).

A checkpoint is driven in the env it was trained in (`EvalTarget`): the observation sizes,
action table, observation scales, simulator parameters and physics of its run's config
(`selfplaydrive.policies.trained_env_kwargs`). The maps are the eval config's; the reward
coefficients are the paper's fixed evaluation values for the suites and long-form (their
scenarios and spawner set them) and the run's training distribution for the diversity
analysis. A built-in driver gets the paper's env.
"""

from __future__ import annotations

import json
import sys
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from selfplaydrive.errors import CheckpointError, ConfigError

ANALYSES = ("suites", "longform", "completion", "diversity")


class SpecPolicy:
    """`policy(obs, env) -> actions` from a spec ("rule_based", "random", "static" or a
    checkpoint path), built once per env it is asked to drive.

    Args:
        spec: Built-in driver name or checkpoint path.
        seed: Seed of the random driver.
        payload: The checkpoint, already loaded (read once for every env of the run).
    """

    def __init__(self, spec: str, seed: int = 0, payload: dict[str, Any] | None = None) -> None:
        self.spec, self.seed, self.payload = str(spec), int(seed), payload
        self._env: Any = None
        self._policy: Any = None

    def __call__(self, obs: Any, env: Any) -> Any:
        if self._env is not env:
            from selfplaydrive.policies import make_policy

            extra = {} if self.payload is None else {"payload": self.payload}
            self._env, self._policy = env, make_policy(self.spec, env, seed=self.seed, **extra)
        return self._policy(obs, env)

    def reset(self) -> None:
        """Forget the recurrent state of the current policy (after an env reset)."""
        if hasattr(self._policy, "reset"):
            self._policy.reset()

    def factory(self, env: Any) -> _Act:
        """The suites' convention: `factory(env) -> act(obs)`, with `act.reset()`."""
        return _Act(self, env)


class _Act:
    """`act(obs)` of one env for `run_suite`, which calls `reset()` after each batch's reset
    (a checkpoint's LSTM state must not carry over from one batch of scenarios to the next)."""

    def __init__(self, policy: SpecPolicy, env: Any) -> None:
        self.policy, self.env = policy, env

    def __call__(self, obs: Any) -> Any:
        return self.policy(obs, self.env)

    def reset(self) -> None:
        if self.policy._env is self.env:  # built for this env: forget its state
            self.policy.reset()


@dataclass
class EvalTarget:
    """What `selfplaydrive eval` evaluates and the env settings it needs.

    Attributes:
        policy: The policy.
        env_kwargs: `VecEnv` arguments of the trained env (empty: the paper's defaults).
        env_source: Where `env_kwargs` come from (a run config path or a phrase), for the log.
        run_config: The training run's config, or None (built-in driver, no run folder).
        obs_dim: Observation width the checkpoint's env produced, when the checkpoint says.
    """

    policy: SpecPolicy
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    env_source: str = "paper defaults"
    run_config: Any = None
    obs_dim: int | None = None


def resolve_target(cfg: Any) -> EvalTarget:
    """The policy of `cfg.policy` and the env it was trained in.

    Raises:
        CheckpointError: `cfg.policy` is neither a built-in name nor a readable checkpoint, or
            `cfg.run_config` is given and unreadable (the message names the file).
    """
    from selfplaydrive.policies import (
        find_run_config,
        is_builtin,
        load_checkpoint,
        load_run_config,
        trained_env_kwargs,
        trained_obs_dim,
    )
    from selfplaydrive.pretrained import resolve_spec

    spec, seed = resolve_spec(str(cfg.policy)), int(cfg.seed)
    if is_builtin(spec):
        return EvalTarget(SpecPolicy(spec, seed), env_source="paper defaults (built-in driver)")
    if not Path(spec).is_file():
        raise CheckpointError(
            "policy: no such file; expected a checkpoint path, pretrained or one of rule_based, random, "
            "static",
            spec,
        )
    payload = load_checkpoint(spec)
    given = cfg.get("run_config")
    cfg_path = Path(str(given)) if given else find_run_config(spec)
    target = EvalTarget(SpecPolicy(spec, seed, payload), obs_dim=trained_obs_dim(payload))
    if cfg_path is None:
        warnings.warn(
            f"checkpoint {spec}: no resolved_config.yaml in its run folder; evaluating in the paper's env "
            "(pass run_config=<run>/resolved_config.yaml if the model was trained with other observation "
            "sizes or scales)",
            UserWarning,
            stacklevel=2,
        )
        return target
    target.run_config = load_run_config(cfg_path)
    target.env_kwargs = trained_env_kwargs(target.run_config)
    target.env_source = str(cfg_path)
    return target


class EvalEnvFactory:
    """Builds every env of the run on the eval maps with the target's settings; fits both the
    suites' `(spawner, num_worlds)` and long-form's `(spawner=, num_worlds=, seed=)` calls.

    Args:
        maps: The eval maps.
        target: The policy and its env settings.
    """

    def __init__(self, maps: list[Any], target: EvalTarget) -> None:
        self.maps, self.target = maps, target
        self.described: dict[str, Any] | None = None

    def __call__(self, spawner: Any, num_worlds: int, seed: int = 0, **kwargs: Any) -> Any:
        from selfplaydrive.sim.vec_env import VecEnv

        env = VecEnv(self.maps, spawner, num_worlds, seed=seed, **{**self.target.env_kwargs, **kwargs})
        want = self.target.obs_dim
        if want is not None and want != env.layout.obs_dim:
            raise CheckpointError(
                f"the checkpoint's env produced observations of width {want}, the eval env (settings from "
                f"{self.target.env_source}) {env.layout.obs_dim}; expected the same: pass "
                "run_config=<training run>/resolved_config.yaml",
                self.target.policy.spec,
            )
        if self.described is None:
            self.described = describe_env(env, self.target.env_source)
        return env


def describe_env(env: Any, source: str) -> dict[str, Any]:
    """JSON-ready facts about an eval env: where its settings come from, observation layout,
    action table, observation scales and physics (written to env.json in the run folder)."""
    table, params = env.action_table, env.params
    if getattr(table, "discrete", False):
        actions = {"accel": [float(v) for v in table.accel], "steer_rad": [float(v) for v in table.steer]}
    else:
        actions = {"high": [float(v) for v in table.high]}  # symmetric: low = -high
    return {
        "settings_from": source,
        "max_objects": int(env.layout.max_objects),
        "max_road": int(env.layout.max_road),
        "obs_dim": int(env.layout.obs_dim),
        "obs_radius": float(env.obs_config.radius),
        "actions": {"kind": type(table).__name__, **actions},
        "params": {
            k: float(getattr(params, k))
            for k in ("dt", "wp_scale", "length_scale", "width_scale", "lateral_scale", "terminate_threshold")
            if hasattr(params, k)
        },
        "physics": type(env.physics).__name__,
        "terminated_vehicle": env.terminated_vehicle,
    }


def run_eval(cfg: Any, run_dir: Path) -> dict[str, Any]:
    """Run `cfg.eval.analyses` on the maps of `cfg.map`; returns {analysis: paths written}.

    Raises:
        ConfigError: An unknown analysis name.
        CheckpointError: `cfg.policy` is no built-in driver and no readable checkpoint.
    """
    from selfplaydrive.builder import build_maps

    analyses = list(cfg.eval.analyses)
    unknown = sorted(set(analyses) - set(ANALYSES))
    if unknown:
        raise ConfigError(f"eval.analyses: unknown {unknown}; valid choices: {', '.join(ANALYSES)}")
    if cfg.get("suites") is not None:  # `suites=[...]`: just these suites
        analyses = ["suites"]
    target = resolve_target(cfg)  # before the maps: a bad checkpoint fails at once
    maps = build_maps(cfg.map)
    make_env = EvalEnvFactory(maps, target)
    _say(f"policy {cfg.policy}; env settings from {target.env_source}; analyses: {', '.join(analyses)}")
    written: dict[str, Any] = {}
    for name in analyses:
        start = time.perf_counter()
        written[name] = RUNNERS[name](cfg, target, make_env, run_dir)
        _say(f"{name}: finished in {time.perf_counter() - start:.1f} s")
    if make_env.described is not None:
        (run_dir / "env.json").write_text(json.dumps(make_env.described, indent=2) + "\n")
    return written


def _say(message: str) -> None:
    """Progress on stderr (stdout carries the report tables)."""
    print(f"selfplaydrive eval: {message}", file=sys.stderr, flush=True)


def _run_suites(cfg: Any, target: EvalTarget, make_env: EvalEnvFactory, run_dir: Path) -> dict[str, Path]:
    from selfplaydrive.eval.report import write_report
    from selfplaydrive.eval.suites import run_all_suites

    result = run_all_suites(
        make_env.maps,
        target.policy.factory,
        counts=suite_counts(cfg),
        seed=int(cfg.seed),
        batch_size=int(cfg.eval.batch_size),
        env_factory=make_env,
        progress=_say,
    )
    write_report(result, run_dir, "suites_detail", "Rule-adherence suites, per scenario")
    return write_report(_suite_summaries(result), run_dir, "suites", "Rule-adherence suites")


def suite_counts(cfg: Any) -> dict[str, int]:
    """Scenarios per suite: `eval.suites`, or only the suites named by ``suites=[...]``.

    Raises:
        ConfigError: ``suites`` is not a list of names, or names a suite `eval.suites` lacks.
    """
    counts = {str(k): int(v) for k, v in dict(cfg.eval.suites).items()}
    chosen = cfg.get("suites")
    if chosen is None:
        return counts
    if isinstance(chosen, str) or not hasattr(chosen, "__iter__"):
        raise ConfigError(f"suites: expected a list of suite names such as [red_lights], got {chosen!r}")
    names = [str(n) for n in chosen]
    unknown = [n for n in names if n not in counts]
    if unknown or not names:
        raise ConfigError(
            f"suites: unknown {unknown or names}; expected names of eval.suites: {', '.join(counts)}"
        )
    return {n: counts[n] for n in names}


def _run_longform(cfg: Any, target: EvalTarget, make_env: EvalEnvFactory, run_dir: Path) -> dict[str, Path]:
    from selfplaydrive.eval.longform import run_longform
    from selfplaydrive.eval.report import write_report

    lf = cfg.eval.longform
    result = run_longform(
        make_env,
        target.policy,
        duration_s=float(lf.duration_s),
        num_worlds=int(lf.num_worlds),
        seed=int(cfg.seed),
        progress=_say,
    )
    return write_report(result.to_dict(), run_dir, "longform", "Long-form self-play")


def _run_diversity(cfg: Any, target: EvalTarget, make_env: EvalEnvFactory, run_dir: Path) -> dict[str, Path]:
    from selfplaydrive.eval.diversity import diversity_summary, run_diversity, save_diversity
    from selfplaydrive.eval.report import write_report

    dv = cfg.eval.diversity
    spawner = _training_spawner(target)
    log = run_diversity(
        make_env,
        target.policy,
        spawner=spawner,
        duration_s=float(dv.duration_s),
        num_worlds=int(dv.num_worlds),
        seed=int(cfg.seed),
        lateral_every=int(dv.lateral_every),
        exposure_every=int(dv.exposure_every),
        progress=_say,
    )
    files = save_diversity(log, run_dir / "diversity")
    summary = {
        "protocol": {
            "duration_s": float(dv.duration_s),
            "num_worlds": int(dv.num_worlds),
            "seed": int(cfg.seed),
            "spawner": "training run's" if target.run_config is not None else "paper's (PaperSpawner())",
        },
        **diversity_summary(log),
    }
    paths = write_report(summary, run_dir, "diversity", "Behaviour diversity (section 5.4)")
    return {**paths, **files}


def _run_completion(cfg: Any, target: EvalTarget, make_env: EvalEnvFactory, run_dir: Path) -> dict[str, Path]:
    """Waypoint completion under the paper's fixed evaluation coefficients, in the policy's
    training spawner (its agents per world, routes and episode lengths), with every missed
    waypoint charged to how its agent ended (`eval.misses`)."""
    from selfplaydrive.eval.collisions import CollisionRecorder
    from selfplaydrive.eval.misses import completion_breakdown
    from selfplaydrive.eval.report import write_report

    c = cfg.eval.completion
    spawner = _training_spawner(target, eval_coefficients=True)
    own = target.run_config is not None and "spawner" in target.run_config
    source = "the training run's spawner" if own else "the paper's spawner"
    env = make_env(spawner, int(c.num_worlds), seed=int(cfg.seed))
    _say(f"completion: {int(c.world_episodes)} world-episodes in {int(c.num_worlds)} worlds ({source}) ...")
    collisions = CollisionRecorder(env)
    table = completion_breakdown(
        env, target.policy, int(c.world_episodes), seed=int(cfg.seed), recorders=[collisions]
    )
    kinds = collisions.breakdown()
    protocol = {
        "coefficients": "the paper's fixed evaluation values (conf/reward/eval.yaml)",
        "spawner": source,
        "num_worlds": int(c.num_worlds),
        "seed": int(cfg.seed),
        "actions": "sampled",
    }
    summary = {"protocol": protocol, **table.to_dict(), "collision_kinds": kinds.to_dict()}
    paths = write_report(summary, run_dir, "completion")
    head = "# Waypoint completion and where the missed waypoints go\n\n"
    lines = [f"- {k}: {v}" for k, v in protocol.items()]
    kinds_md = "## What the vehicle collisions are (`eval.collisions`)\n\n" + kinds.markdown()
    body = table.markdown() + "\n\n" + kinds_md
    paths["markdown"].write_text(head + "\n".join(lines) + "\n\n" + body + "\n")
    return paths


def _training_spawner(target: EvalTarget, eval_coefficients: bool = False) -> Any:
    """The spawner of the policy's training run, else the paper's; its coefficients drawn per agent
    from the run's reward ranges (section 2.3, also for a run trained at the fixed values with
    `reward=eval`, the main job's default), or (`eval_coefficients`) the paper's fixed evaluation
    values. The run's training curricula (turn-lane starts and worlds, `CURRICULUM_OPTIONS`) are
    off."""
    from selfplaydrive.scenario.conditioning import ConditioningSampler
    from selfplaydrive.scenario.spawner import PaperSpawner, without_curricula

    if target.run_config is None or "spawner" not in target.run_config:
        return PaperSpawner(conditioning=ConditioningSampler(mode="eval") if eval_coefficients else None)
    from omegaconf import OmegaConf

    from selfplaydrive.builder import build_spawner

    run_cfg = OmegaConf.create(OmegaConf.to_container(target.run_config, resolve=False))
    without_curricula(run_cfg.spawner)  # turn-lane starts and worlds train; they are not the world
    run_cfg.reward.mode = "eval" if eval_coefficients else "train"
    return build_spawner(run_cfg)  # with the run's reward group's sampler


RUNNERS = {
    "suites": _run_suites,
    "longform": _run_longform,
    "completion": _run_completion,
    "diversity": _run_diversity,
}


def _suite_summaries(result: dict[str, Any]) -> dict[str, Any]:
    """The per-suite summaries (proportions with intervals) without the per-scenario rows."""
    keep = ("requested", "generated", "summary", "hidden_summary", "changed")
    return {name: {k: v for k, v in r.items() if k in keep} for name, r in result.items()}


def eval_task(cfg: Any) -> dict[str, Any]:
    """Hydra task of `selfplaydrive eval`."""
    from selfplaydrive.runs import write_run_meta

    run_dir = write_run_meta(cfg)
    written = run_eval(cfg, run_dir)
    for name, paths in written.items():
        print(f"{name}: {paths['markdown']}")
        print(Path(paths["markdown"]).read_text())
    return written
