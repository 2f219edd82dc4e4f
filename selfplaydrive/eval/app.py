"""`selfplaydrive eval`: run the chosen analyses for a checkpoint or a built-in driver and
write JSON plus a markdown table per analysis into the run folder (paper section 5)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from selfplaydrive.errors import ConfigError

ANALYSES = ("suites", "longform")


class SpecPolicy:
    """`policy(obs, env) -> actions` from a spec ("rule_based", "random", "static" or a
    checkpoint path), built once per env it is asked to drive."""

    def __init__(self, spec: str, seed: int = 0) -> None:
        self.spec, self.seed = str(spec), int(seed)
        self._env: Any = None
        self._policy: Any = None

    def __call__(self, obs: Any, env: Any) -> Any:
        if self._env is not env:
            from selfplaydrive.render.policies import make_policy

            self._env, self._policy = env, make_policy(self.spec, env, seed=self.seed)
        return self._policy(obs, env)

    def factory(self, env: Any) -> Any:
        """The suites' convention: `factory(env) -> act(obs)`."""
        return lambda obs: self(obs, env)


def run_eval(cfg: Any, run_dir: Path) -> dict[str, Any]:
    """Run `cfg.eval.analyses` on the maps of `cfg.map`; returns {analysis: paths written}."""
    from selfplaydrive.builder import build_maps
    from selfplaydrive.eval.report import write_report

    unknown = sorted(set(cfg.eval.analyses) - set(ANALYSES))
    if unknown:
        raise ConfigError(f"eval.analyses: unknown {unknown}; valid choices: {', '.join(ANALYSES)}")
    maps = build_maps(cfg.map)
    policy = SpecPolicy(cfg.policy, seed=cfg.seed)
    written: dict[str, Any] = {}
    if "suites" in cfg.eval.analyses:
        from selfplaydrive.eval.suites import run_all_suites

        result = run_all_suites(
            maps, policy.factory, counts=dict(cfg.eval.suites), seed=cfg.seed, batch_size=cfg.eval.batch_size
        )
        written["suites"] = write_report(_suite_summaries(result), run_dir, "suites", "Rule-adherence suites")
        write_report(result, run_dir, "suites_detail", "Rule-adherence suites, per scenario")
    if "longform" in cfg.eval.analyses:
        from selfplaydrive.eval.longform import run_longform

        lf = cfg.eval.longform
        result = run_longform(maps, policy, duration_s=lf.duration_s, num_worlds=lf.num_worlds, seed=cfg.seed)
        written["longform"] = write_report(result.to_dict(), run_dir, "longform", "Long-form self-play")
    return written


def _suite_summaries(result: dict[str, Any]) -> dict[str, Any]:
    """The per-suite summaries (proportions with intervals) without the per-scenario rows."""
    keep = ("requested", "generated", "summary", "hidden_summary", "changed")
    return {name: {k: v for k, v in r.items() if k in keep} for name, r in result.items()}


def eval_task(cfg: Any) -> dict[str, Any]:
    """Hydra task of `selfplaydrive eval`."""
    from selfplaydrive.hydra_app import write_run_meta

    run_dir = write_run_meta(cfg)
    written = run_eval(cfg, run_dir)
    for name, paths in written.items():
        print(f"{name}: {paths['markdown']}")
        print(Path(paths["markdown"]).read_text())
    return written
