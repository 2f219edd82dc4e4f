"""`selfplaydrive eval`: reports of every analysis with progress lines, a checkpoint evaluated in
the env it was trained in (observation sizes, action table, scales) with the fixed evaluation
coefficients, checkpoint errors that name the file, the diversity analysis and the help text."""

from __future__ import annotations

import dataclasses
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

import selfplaydrive.conf
from selfplaydrive.cli import main
from selfplaydrive.errors import CheckpointError
from selfplaydrive.eval.collisions import KINDS

TINY_SUITES = ["eval.suites.turn_lanes=1", "eval.suites.stop_lines=1", "eval.suites.crosswalks=1"]
# what the fake training run changes from the paper's env (and from experiment=laptop)
TRAINED = {"max_objects": 16, "max_road": 64, "accel": [-4.0, 0.0, 4.0], "wp_scale": 40.0, "num_agents": 4}


def eval_vector() -> np.ndarray:
    """The fixed evaluation coefficients of conf/reward/eval.yaml."""
    from omegaconf import OmegaConf

    from selfplaydrive.builder import instantiate

    node = OmegaConf.load(Path(selfplaydrive.conf.__file__).parent / "reward" / "eval.yaml")
    return instantiate(node).conditioning.eval_vector()


@pytest.fixture(scope="module")
def trained_run(tmp_path_factory) -> Path:
    """A run folder of a one-update `selfplaydrive train` with non-default observation sizes,
    action table and waypoint scale (a tiny model, 4 agents per world)."""
    pytest.importorskip("torch")
    run = tmp_path_factory.mktemp("train") / "run"
    code = main(
        [
            "train",
            f"hydra.run.dir={run}",
            "logger=none",
            "env.num_worlds=1",
            f"spawner.num_agents={TRAINED['num_agents']}",
            f"obs.max_objects={TRAINED['max_objects']}",
            f"obs.max_road={TRAINED['max_road']}",
            f"env.actions.accel=[{','.join(map(str, TRAINED['accel']))}]",
            f"env.params.wp_scale={TRAINED['wp_scale']}",
            "model.input_size=8",
            "model.hidden_size=16",
            "model.lstm_size=12",
            "trainer.total_steps=32",
            "trainer.rollout_length=8",
            "trainer.eval_episodes=1",
            "trainer.eval_max_steps=10",
            "trainer.progress_bar=false",
        ]
    )
    assert code == 0
    assert (run / "checkpoints" / "final.pt").is_file() and (run / "resolved_config.yaml").is_file()
    return run


def test_eval_rule_based_writes_reports(tmp_path, capsys):
    out = tmp_path / "run"
    code = main(
        [
            "eval",
            "eval=quick",
            "eval.suites.turn_lanes=2",
            "eval.suites.stop_lines=2",
            "eval.suites.crosswalks=2",
            "eval.longform.duration_s=10",
            "eval.longform.num_worlds=1",
            f"hydra.run.dir={out}",
        ]
    )
    assert code == 0
    for name in ("suites", "longform"):
        data = json.loads((out / f"{name}.json").read_text())
        assert data, f"{name}.json is empty"
        assert (out / f"{name}.md").read_text().startswith("## ")
    suites = json.loads((out / "suites.json").read_text())
    failure_modes = {"red_lights", "stop_signs", "spawn_sanity"}
    assert set(suites) == {"turn_lanes", "stop_lines", "crosswalks"} | failure_modes
    assert suites["stop_lines"]["generated"] == 2
    assert suites["red_lights"]["generated"] == 4 and suites["spawn_sanity"]["summary"]["n"] == 8
    longform = json.loads((out / "longform.json").read_text())
    assert longform["km"] > 0
    # completion: the eval=quick option's 2 world-episodes in the paper's spawner, every missed
    # waypoint charged to one outcome
    done = json.loads((out / "completion.json").read_text())
    assert done["episodes"] == 2 and done["protocol"]["spawner"] == "the paper's spawner"
    outcomes = done["outcomes"].values()
    assert sum(o["agents"] for o in outcomes) == done["agents"] > 0
    missed = sum(o["missed_share"] for o in outcomes)
    assert missed == pytest.approx(1.0 - done["waypoint_completion"])
    assert "| vehicle_collision |" in (out / "completion.md").read_text()
    # the same rollout's vehicle collisions by kind (eval.collisions)
    kinds = done["collision_kinds"]
    assert sum(kinds[k]["count"] for k in KINDS) == kinds["collisions"]
    assert "| head_on |" in (out / "completion.md").read_text()
    meta = json.loads((out / "run_meta.json").read_text())
    assert meta["seed"] == 0
    assert len(meta["git_commit"]) == 40 or meta["git_commit"] == "unknown"
    # a built-in driver is evaluated in the paper's env
    env = json.loads((out / "env.json").read_text())
    assert (env["max_objects"], env["max_road"], env["params"]["wp_scale"]) == (63, 200, 200.0)
    assert env["settings_from"].startswith("paper defaults")
    # progress: a line before and after every suite, and through the long-form run
    err = capsys.readouterr().err
    for suite in ("turn_lanes", "stop_lines", "crosswalks"):
        assert f"suites: {suite}: 2 scenarios generated" in err or f"suites: {suite}: 4 scenarios" in err
        assert re.search(rf"suites: {suite}: done in \d+\.\d s", err), err
    assert "longform: 5.0/10.0 s simulated" in err and "longform: 10.0/10.0 s simulated" in err
    assert re.search(r"longform: finished in \d+\.\d s", err)


def test_checkpoint_is_evaluated_in_its_training_env(trained_run, tmp_path, monkeypatch):
    from selfplaydrive.eval.app import SpecPolicy

    seen = []
    call = SpecPolicy.__call__

    def spy(self, obs, env):
        acting = np.asarray(env.masks, bool)
        seen.append(
            {
                "layout": (env.layout.max_objects, env.layout.max_road),
                "obs_width": obs.shape[1],
                "nvec": tuple(int(n) for n in env.action_space.nvec),
                "wp_scale": float(env.params.wp_scale),
                "agents": env.agents_per_world,
                "coeffs": np.array(env.state.coeffs)[acting],
            }
        )
        return call(self, obs, env)

    monkeypatch.setattr(SpecPolicy, "__call__", spy)
    out = tmp_path / "eval"
    code = main(
        [
            "eval",
            f"policy={trained_run / 'checkpoints' / 'final.pt'}",
            "eval=quick",
            "eval.analyses=[suites,longform,diversity]",
            *TINY_SUITES,
            "eval.longform.duration_s=2",
            "eval.longform.num_worlds=1",
            "eval.diversity.duration_s=2",
            "eval.diversity.num_worlds=1",
            f"hydra.run.dir={out}",
        ]
    )
    assert code == 0
    assert {s["agents"] for s in seen} == {2, 32, TRAINED["num_agents"]}  # suites, long-form, diversity
    for s in seen:
        assert s["layout"] == (TRAINED["max_objects"], TRAINED["max_road"])
        assert s["nvec"] == (len(TRAINED["accel"]), 13)
        assert s["wp_scale"] == TRAINED["wp_scale"]
    want = eval_vector()
    evaluated = np.concatenate([s["coeffs"] for s in seen if s["agents"] != TRAINED["num_agents"]])
    assert len(evaluated) > 0
    np.testing.assert_allclose(evaluated, np.broadcast_to(want, evaluated.shape), rtol=1e-6)
    # diversity draws the run's training distribution: the coefficients vary between agents
    trained = np.concatenate([s["coeffs"] for s in seen if s["agents"] == TRAINED["num_agents"]])
    assert np.ptp(trained, axis=0).max() > 0.1
    env = json.loads((out / "env.json").read_text())
    assert env["settings_from"] == str(trained_run / "resolved_config.yaml")
    assert (env["max_objects"], env["max_road"]) == (TRAINED["max_objects"], TRAINED["max_road"])
    assert env["actions"]["accel"] == TRAINED["accel"]
    for name in ("suites", "longform", "diversity"):
        assert (out / f"{name}.md").is_file()


def test_checkpoint_without_run_folder_needs_run_config(trained_run, tmp_path):
    from selfplaydrive.builder import build_maps, compose
    from selfplaydrive.eval.app import EvalEnvFactory, resolve_target
    from selfplaydrive.scenario.spawner import PaperSpawner

    loose = tmp_path / "moved" / "final.pt"
    loose.parent.mkdir()
    shutil.copy(trained_run / "checkpoints" / "final.pt", loose)
    cfg = compose("eval", [f"policy={loose}"])
    with pytest.warns(UserWarning, match="no resolved_config.yaml"):
        target = resolve_target(cfg)
    maps = build_maps(cfg.map)
    # the paper's env gives wider observations than the checkpoint's env did: refused, named
    with pytest.raises(CheckpointError, match=rf"width {target.obs_dim}.*run_config=") as info:
        EvalEnvFactory(maps, target)(PaperSpawner(num_agents=2), 1)
    assert info.value.path == str(loose)
    cfg = compose("eval", [f"policy={loose}", f"run_config={trained_run / 'resolved_config.yaml'}"])
    target = resolve_target(cfg)
    env = EvalEnvFactory(maps, target)(PaperSpawner(num_agents=2), 1)
    assert env.layout.obs_dim == target.obs_dim
    assert env.layout.max_objects == TRAINED["max_objects"]


def test_run_config_of_the_old_layout_gives_the_same_trained_env(trained_run, tmp_path):
    """A resolved_config.yaml written before the reward group held every reward setting
    (constants under env.params, the sampler in spawner.conditioning) rebuilds the same env."""
    from omegaconf import OmegaConf

    from selfplaydrive.builder import compose
    from selfplaydrive.eval.app import resolve_target
    from selfplaydrive.sim.reward_settings import CONSTANTS

    old = OmegaConf.load(trained_run / "resolved_config.yaml")
    for key in ("velocity_reward", "waypoint_reward", "terminate_threshold", "comfort_limit"):
        old.env.params[key] = old.reward.pop(key)
    old.env.params.velocity_reward = 0.03  # a value the new layout's defaults do not have
    for key in set(CONSTANTS) - set(old.env.params):
        old.reward.pop(key)
    old.reward._target_ = "selfplaydrive.scenario.conditioning.ConditioningSampler"
    old.spawner.conditioning = OmegaConf.masked_copy(old.reward, [k for k in old.reward if k != "terms"])
    OmegaConf.save(old, tmp_path / "old.yaml")
    ckpt = trained_run / "checkpoints" / "final.pt"
    new = resolve_target(compose("eval", [f"policy={ckpt}"])).env_kwargs["params"]
    with pytest.warns(UserWarning, match=r"old layout.*env.params.velocity_reward -> reward.velocity_reward"):
        got = resolve_target(compose("eval", [f"policy={ckpt}", f"run_config={tmp_path / 'old.yaml'}"]))
    assert got.env_kwargs["params"] == dataclasses.replace(new, velocity_reward=0.03)
    assert got.env_kwargs["params"].wp_scale == TRAINED["wp_scale"]


@pytest.mark.parametrize("kind", ["missing", "text", "foreign_torch", "directory"])
def test_bad_checkpoint_is_a_checkpoint_error_naming_the_file(kind, tmp_path):
    from selfplaydrive.builder import compose
    from selfplaydrive.eval.app import run_eval

    path = tmp_path / "policy.pt"
    if kind == "missing":
        path = Path("/nonexistent.pt")
    elif kind == "text":
        path.write_text("not a checkpoint\n")
    elif kind == "foreign_torch":
        torch = pytest.importorskip("torch")
        torch.save({"weights": torch.zeros(3)}, path)
    else:
        path.mkdir()
    cfg = compose("eval", [f"policy={path}"])
    with pytest.raises(CheckpointError) as info:
        run_eval(cfg, tmp_path / "out")
    assert info.value.path == str(path)
    assert str(path) in str(info.value)
    assert not (tmp_path / "out" / "suites.json").exists()


def test_eval_diversity_from_the_cli(tmp_path, capsys):
    out = tmp_path / "run"
    code = main(
        [
            "eval",
            "eval=diversity",
            "eval.diversity.duration_s=3",
            "eval.diversity.num_worlds=2",
            "eval.diversity.exposure_every=5",
            f"hydra.run.dir={out}",
        ]
    )
    assert code == 0
    assert not (out / "suites.json").exists() and not (out / "longform.json").exists()
    summary = json.loads((out / "diversity.json").read_text())
    assert summary["protocol"]["num_worlds"] == 2
    assert summary["lateral_samples"] > 0
    binned = json.loads((out / "diversity" / "diversity.json").read_text())
    exposure = np.array(binned["offroad"]["exposure"])
    # 2 worlds x 32 agents sampled every 5 of 30 steps, C_offroad ~ U(0, 1): most bins are hit
    assert exposure.sum() > 0 and np.count_nonzero(exposure) >= 5
    for name in ("offroad_vs_coefficient.png", "collision_heatmap.png", "lateral_vs_bias.png"):
        assert (out / "diversity" / name).stat().st_size > 0
    err = capsys.readouterr().err
    assert "diversity: 3.0/3.0 s simulated" in err


def test_eval_help_names_the_command_and_its_groups(capsys):
    from selfplaydrive.builder import valid_options

    with pytest.raises(SystemExit) as info:
        main(["eval", "--help"])
    assert info.value.code == 0
    text = capsys.readouterr().out
    assert text.startswith("selfplaydrive eval:")
    assert "hydra_app" not in text
    section = text.split("== Configuration groups")[1].split("== Config ==")[0]
    groups = dict(re.findall(r"^(\w+): ([\w, ]+?)\s{2,}", section, flags=re.MULTILINE))
    assert set(groups) == {"map", "eval"}  # no training-only groups (trainer, model, logger ...)
    for group, options in groups.items():
        assert options.split(", ") == valid_options(group), f"help lists stale options of {group}"


def test_eval_unknown_analysis_is_a_config_error(tmp_path):
    from selfplaydrive.builder import compose
    from selfplaydrive.errors import ConfigError
    from selfplaydrive.eval.app import run_eval

    cfg = compose("eval", ["eval=quick", "eval.analyses=[suites,carla]"])
    with pytest.raises(ConfigError, match=r"carla.*valid choices: suites, longform, completion, diversity"):
        run_eval(cfg, tmp_path)
