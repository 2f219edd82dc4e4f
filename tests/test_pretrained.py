"""The shipped pretrained policy (selfplaydrive/pretrained/, issue #16 item 3): its files are
package data and small, its recorded observation/action layout is the one the env builds from
its config today (this fails when the layout changes: train and ship it again, docs/training.md
"The pretrained policy"), it loads and drives, and `policy=pretrained` / `driver=pretrained`
reach it from `selfplaydrive eval` and `selfplaydrive render`."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from loadfile import load_file

from selfplaydrive import pretrained
from selfplaydrive.errors import CheckpointError
from selfplaydrive.obs.layout import ObsLayout

torch = pytest.importorskip("torch")

ROOT = Path(__file__).resolve().parents[1]
MAX_BYTES = 5 * 2**20  # "a few MB at most"
RETRAIN = (
    "the shipped pretrained policy no longer matches the env built from its config: train it again and "
    "ship it (docs/training.md, 'The pretrained policy')"
)


@pytest.fixture(scope="module")
def env():
    return pretrained.build_env(num_worlds=2, seed=0)


def test_files_are_package_data_and_small():
    meta = pretrained.load_metadata()
    for key in ("command", "seed", "start_utc", "end_utc", "duration_s", "machine", "git_commit", "layout"):
        assert key in meta, key
    size = pretrained.checkpoint_path().stat().st_size
    assert size == meta["size_bytes"] and size < MAX_BYTES
    assert (pretrained.FOLDER / pretrained.RUN_CONFIG).is_file()
    tomllib = pytest.importorskip("tomllib", reason="tomllib needs Python >= 3.11")
    data = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]
    assert {"*.pt", "*.json", "*.md"} <= set(data["selfplaydrive.pretrained"])
    assert "*.yaml" in data["*"]


def test_layout_signature_hand_computed():
    """19 ego + 2 objects x 9 + 3 segments x 8 = 61 columns; a 3 x 2 action table."""
    table = SimpleNamespace(accel=np.array([-1.0, 0.0, 1.0]), steer=np.array([-0.1, 0.1]))
    fake = SimpleNamespace(
        layout=ObsLayout(max_objects=2, max_road=3),
        action_table=table,
        action_space=SimpleNamespace(nvec=[3, 2]),
    )
    sig = pretrained.layout_signature(fake)
    assert sig == {
        "obs_dim": 61,
        "blocks": {"ego": [19], "objects": [2, 9], "road": [3, 8], "extra": [0]},
        "action_kind": "SimpleNamespace",
        "action_nvec": [3, 2],
        "accel": [-1.0, 0.0, 1.0],
        "steer_rad": [-0.1, 0.1],
    }


def test_recorded_layout_matches_the_env(env):
    assert pretrained.layout_signature(env) == pretrained.load_metadata()["layout"], RETRAIN


def test_weights_fit_and_a_batched_forward_pass_is_finite(env):
    from selfplaydrive.policies import load_checkpoint, model_from_checkpoint

    path = pretrained.checkpoint_path()
    payload = load_checkpoint(path)
    assert not {"optimizer", "env"} & set(payload)  # policy-only
    try:
        model = model_from_checkpoint(payload, env, path).eval()
    except CheckpointError as exc:
        pytest.fail(f"{RETRAIN}: {exc}")
    obs = torch.from_numpy(env.reset(seed=0).copy())
    n = obs.shape[0]
    with torch.no_grad():
        logits, value, _ = model(obs, model.initial_state(n, "cpu"), torch.ones(n, dtype=torch.bool))
    assert logits.shape == (n, sum(pretrained.load_metadata()["layout"]["action_nvec"]))
    assert value.shape[0] == n and torch.isfinite(logits).all() and torch.isfinite(value).all()


def test_policy_drives_a_few_steps(env):
    from selfplaydrive.policies import make_policy

    obs = env.reset(seed=1)
    policy = make_policy("pretrained", env)
    nvec = np.asarray(env.action_space.nvec)
    for _ in range(5):
        actions = policy(obs, env)
        assert actions.shape == (env.num_agents, 2)
        assert ((actions >= 0) & (actions < nvec)).all()
        env.step(actions)
        obs = env.observations
    assert np.isfinite(obs).all()


def test_resolve_spec_and_a_missing_file(monkeypatch, tmp_path):
    assert pretrained.resolve_spec("pretrained") == str(pretrained.FOLDER / pretrained.CHECKPOINT)
    assert pretrained.resolve_spec("rule_based") == "rule_based"
    assert pretrained.resolve_spec("x/final.pt") == "x/final.pt"
    monkeypatch.setattr(pretrained, "FOLDER", tmp_path)
    with pytest.raises(CheckpointError, match="pretrained policy is missing"):
        pretrained.resolve_spec("pretrained")


def test_eval_finds_the_run_config():
    from omegaconf import OmegaConf

    from selfplaydrive.eval.app import resolve_target

    target = resolve_target(OmegaConf.create({"policy": "pretrained", "seed": 0}))
    assert target.env_source == str(pretrained.FOLDER / pretrained.RUN_CONFIG)
    assert target.policy.spec == str(pretrained.checkpoint_path())
    assert (
        target.env_kwargs["obs"].max_objects == pretrained.load_metadata()["layout"]["blocks"]["objects"][0]
    )


def test_render_cli_drives_the_pretrained_policy(tmp_path):
    from selfplaydrive.cli import main

    out = tmp_path / "p.gif"
    args = ["render", "policy=pretrained", "steps=2", "size=64", f"output={out}", f"hydra.run.dir={tmp_path}"]
    assert main(args) == 0 and out.is_file()


def test_eval_completion_uses_the_training_spawner_with_evaluation_coefficients(tmp_path):
    """`selfplaydrive eval policy=pretrained` measures waypoint completion in the env the policy
    was trained in (its config's agents per world) under the paper's fixed evaluation coefficients."""
    import json

    from selfplaydrive.cli import main
    from selfplaydrive.policies import load_run_config

    trained = int(load_run_config(pretrained.FOLDER / pretrained.RUN_CONFIG).spawner.num_agents)
    out = tmp_path / "run"
    args = ["eval", "policy=pretrained", "eval=quick", "eval.analyses=[completion]", f"hydra.run.dir={out}"]
    assert main([*args, "eval.completion.world_episodes=1", "eval.completion.num_worlds=1"]) == 0
    done = json.loads((out / "completion.json").read_text())
    assert done["protocol"]["spawner"] == "the training run's spawner"
    assert done["episodes"] == 1 and 0 < done["agents"] <= trained
    assert 0.0 <= done["waypoint_completion"] <= 1.0


def test_evaluations_switch_the_training_curricula_off():
    """Turn-lane starts and worlds are training curricula: the completion and diversity runs of
    `selfplaydrive eval` (and `pretrained_report.py`) score a policy without them."""
    from types import SimpleNamespace

    from omegaconf import OmegaConf

    from selfplaydrive.eval.app import _training_spawner
    from selfplaydrive.policies import load_run_config
    from selfplaydrive.scenario.spawner import CURRICULUM_OPTIONS, without_curricula

    run_cfg = load_run_config(pretrained.FOLDER / pretrained.RUN_CONFIG)
    run_cfg.spawner.turn_lane_worlds, run_cfg.spawner.turn_lane_starts = 0.5, 3
    # as if trained at the fixed values (reward=eval, the main job's default): the diversity run
    # still draws the coefficients per agent from the run's ranges
    run_cfg.reward.mode = "eval"
    before = OmegaConf.to_container(run_cfg)
    for eval_coefficients in (False, True):
        spawner = _training_spawner(SimpleNamespace(run_config=run_cfg), eval_coefficients)
        assert (spawner.turn_lane_worlds, spawner.turn_lane_starts) == (0.0, 0)
        assert spawner.num_agents == run_cfg.spawner.num_agents
        assert spawner.conditioning.mode == ("eval" if eval_coefficients else "train")
    assert OmegaConf.to_container(run_cfg) == before  # the run's own config is left as it was
    off = without_curricula({"num_agents": 8, "turn_lane_worlds": 0.25})
    assert off == {"num_agents": 8, "turn_lane_worlds": 0.0}
    assert set(CURRICULUM_OPTIONS) == {"turn_lane_starts", "turn_lane_worlds"}


def test_evaluation_config_sets_up_the_papers_protocol(tmp_path):
    from omegaconf import OmegaConf

    from selfplaydrive.policies import load_run_config

    run = load_run_config(pretrained.FOLDER / pretrained.RUN_CONFIG)
    cfg = pretrained.evaluation_config("default", agents=32)
    assert cfg.reward.mode == "eval" and cfg.env.num_threads == 1 and cfg.spawner.num_agents == 32
    assert cfg.spawner.turn_lane_worlds == 0.0 and cfg.spawner.turn_lane_starts == 0
    assert cfg.map.spec == "default"
    kept = pretrained.evaluation_config()  # the run's own maps and agents
    assert OmegaConf.to_container(kept.map) == OmegaConf.to_container(run.map)
    assert kept.spawner.num_agents == run.spawner.num_agents
    other = OmegaConf.to_container(run)
    other["obs"]["max_road"] = 17
    other["model"]["lstm_size"] = 256  # a candidate of other sizes (init_widen) brings its model
    (tmp_path / "resolved_config.yaml").write_text(OmegaConf.to_yaml(OmegaConf.create(other)))
    candidate = pretrained.evaluation_config(sizes_from=tmp_path / "resolved_config.yaml")
    assert candidate.obs.max_road == 17 and candidate.model.lstm_size == 256
    assert candidate.spawner.num_agents == run.spawner.num_agents and run.model.lstm_size == 128


def _report_script():
    return load_file(ROOT / "benchmarks" / "pretrained_report.py", "pretrained_report")


def test_report_rows_record_collision_kinds_and_the_markdown_tables_them():
    """`benchmarks/pretrained_report.py`: each completion row holds its vehicle collisions by
    kind, from the same rollout as its rates, and REPORT.md tables them."""
    from selfplaydrive.eval.collisions import KINDS

    report = _report_script()
    row = report.completion_eval("default", 4, 1, False, pretrained.checkpoint_path())
    kinds = row["collision_kinds"]
    assert row["agents_per_world"] == 4 and set(KINDS) <= set(kinds)
    assert kinds["collisions"] == sum(kinds[k]["count"] for k in KINDS)
    assert all(0.0 <= kinds[k]["share_junction"] <= 1.0 for k in KINDS if kinds[k]["count"])
    made = {
        "collisions": 5,
        **{k: {"count": c, "share": c / 5} for k, c in zip(KINDS, (2, 0, 3, 0), strict=True)},
    }
    made["head_on"] = {"count": 0, "share": 0.0, "share_junction": float("nan")}
    made["crossing"]["share_junction"] = 2 / 3
    none = {"collisions": 0, **{k: {"count": 0, "share": float("nan")} for k in KINDS}}
    rows = [
        {"agents_per_world": 16, "actions": "sampled", "collision_kinds": made},
        {"agents_per_world": 32, "actions": "greedy", "collision_kinds": none},
        {"agents_per_world": 32, "actions": "sampled"},  # a report written before the kinds
    ]
    lines = report.kind_lines(rows)
    # crossing recorded where its collisions were (2 of 3 at a junction); static (an older
    # row format) did not; head-on had none
    assert "| 16 | sampled | 5 | 2 (40.0 %) | 0 (0.0 %) | 3 (60.0 %; 2 at a junction) | 0 (0.0 %) |" in lines
    assert "| 32 | greedy | 0 | 0 | 0 | 0 | 0 |" in lines
    assert len([x for x in lines if x.startswith("| 32")]) == 1
    assert report.kind_lines(rows[2:]) == []


def test_report_seed_replaces_the_worlds_and_rows_do_not_repeat():
    """`completion_eval(seed=...)` evaluates on another set of worlds (the row records its seed);
    a run trained at the paper's 32 agents gets its completion rows once, not twice."""
    report = _report_script()
    run_seed = int(pretrained.evaluation_config().seed)
    own = report.completion_eval("default", 4, 1, True, pretrained.checkpoint_path())
    other = report.completion_eval("default", 4, 1, True, pretrained.checkpoint_path(), seed=run_seed + 1)
    assert own["seed"] == run_seed and other["seed"] == run_seed + 1
    assert (own["km"], own["agent_episodes"]) != (other["km"], other["agent_episodes"])
    assert report.row_agents(report.PAPER_AGENTS) == [None]
    assert report.row_agents(16) == [None, report.PAPER_AGENTS]


def test_report_judges_completion_on_the_mean_over_sets_of_worlds():
    """Hand-computed: sets at 70, 80 and 90 % have the mean 80 % and the Student-t interval
    80 +- t(0.975, 2) * 10 / sqrt(3) = 80 +- 24.84 %; the target line uses that mean, not the
    best single row."""
    report = _report_script()
    rows = [
        {"agents_per_world": 32, "actions": "greedy", "episodes": 32.0, "seed": s, "waypoint_completion": c}
        for s, c in ((1001, 0.7), (1002, 0.8), (1003, 0.9))
    ]
    sets = report.pool_sets(rows)
    assert sets["seeds"] == [1001, 1002, 1003] and sets["episodes_per_set"] == 32
    assert sets["mean"] == pytest.approx(0.8)
    assert sets["lo"] == pytest.approx(0.8 - 0.24841, abs=1e-4)
    assert sets["hi"] == pytest.approx(0.8 + 0.24841, abs=1e-4)
    lines = report.set_lines(sets)
    assert "| 1002 | 80.0 % | nan | nan |" in lines and any("mean **80.0 %**" in x for x in lines)
    assert report.set_lines(None) == []
    lone = {"agents_per_world": 32, "actions": "greedy", "waypoint_completion": 0.95}
    rep = {
        "completion": [lone],
        "completion_sets": sets,
        "eval": {
            "turn_lanes": {"value": 0.9},
            "longform": {"km_between_incidents": {"value": 2.0}},
        },
    }
    sets["mean"] = 0.81  # (the mean above is 0.8 only up to float rounding)
    verdicts = report.target_lines({"maps": {"default": rep}})
    head = "- map=default, completion (mean of 3 sets, 32 agents, greedy): 81.0 %"
    assert verdicts[0] == head + ", target >= 80.0 %: met"
    sets["mean"] = 0.79  # below the target: the best row's 95 % no longer counts
    assert "not met: 79.0 %" in report.target_lines({"maps": {"default": rep}})[0]
    del rep["completion_sets"]  # a report written before the sets: the best row, as before
    assert "completion (best row; worst 95.0 %): 95.0 %" in report.target_lines({"maps": {"default": rep}})[0]


def _select_script():
    return load_file(ROOT / "benchmarks" / "select_candidates.py", "select_candidates")


def test_candidate_selection_refuses_the_held_out_sets_and_pairs_by_set():
    """The report's held-out seeds cannot be used to pick a policy; hand-computed paired
    differences: (+2, +4, +6) points over three sets -> +4 +- t(0.975, 2) * 2 / sqrt(3) = +4 +- 4.97."""
    select = _select_script()
    assert not set(select.VALIDATION_SEEDS) & set(select.pretrained_report.SET_SEEDS)
    with pytest.raises(ValueError, match=r"\[1003\] are the report's held-out sets"):
        select.check_seeds([29, 1003])
    with pytest.raises(ValueError, match="repeats a seed"):
        select.check_seeds([29, 29])
    with pytest.raises(FileNotFoundError, match=r"nope\.pt"):
        select.resolve("nope.pt")
    diffs = select.paired({"base": [0.70, 0.80, 0.90], "new": [0.72, 0.84, 0.96]}, "base")
    assert list(diffs) == ["new"]
    assert diffs["new"]["mean"] == pytest.approx(0.04)
    assert diffs["new"]["lo"] == pytest.approx(0.04 - 0.04968, abs=1e-4)
    assert diffs["new"]["hi"] == pytest.approx(0.04 + 0.04968, abs=1e-4)


def test_candidate_selection_on_real_worlds_compares_like_with_like(tmp_path):
    """The same weights under two names drive the same worlds: every paired difference is
    exactly zero; two seeds give two sets of worlds."""
    import shutil

    select = _select_script()
    copy = tmp_path / "copy.pt"
    shutil.copy(pretrained.checkpoint_path(), copy)
    with pytest.raises(ValueError, match="named twice"):
        select.evaluate(["pretrained", "pretrained"], [29], 1, [], agents=4)
    result = select.evaluate(["pretrained", str(copy)], [29, 30], 1, [], agents=4)
    rows = result["candidates"]
    assert rows["pretrained"]["completion"] == rows[str(copy)]["completion"]
    assert len(rows["pretrained"]["completion"]) == 2
    assert result["paired"][str(copy)]["mean"] == 0.0
    lines = select.markdown(result)
    assert lines[0].startswith("| candidate | 29 | 30 | mean |") and "| baseline |" in lines[2]
    assert "| +0.0 (+0.0 to +0.0) |" in lines[3]


def test_report_names_a_soup_and_its_runs():
    """A shipped soup (no update of its own) is described by its ingredients, one row each;
    a run's checkpoint by its update and steps, as before."""
    report = _report_script()
    run = {"command": "selfplaydrive train seed=1", "update": 10, "slot_steps": 100, "agent_steps": 80}
    assert "update 10, 100 slot-steps (80 agent-steps)" in report.policy_line(run)
    parts = [
        {"run": "a", "seed": 51, "slot_steps": 6000000, "command": "selfplaydrive train seed=51"},
        {"run": "b", "seed": 53, "slot_steps": 6000000, "command": "selfplaydrive train seed=53"},
    ]
    soup = {"command": "python -m selfplaydrive.trainers.soup x a b", "update": None, "ingredients": parts}
    assert "the mean of the weights of 2 checkpoints" in report.policy_line(soup)
    lines = report.training_lines(soup)
    assert "| b | 53 | 6000000 | `selfplaydrive train seed=53` |" in lines
    assert not any(x.startswith("| update |") for x in lines)
