"""benchmarks/bench_train.py: the baseline export and import overlay, and the summary."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from ppo_helpers import load_benchmark

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def bench():
    return load_benchmark("bench_train")


def test_export_and_overlay_find_the_baselines_modules(bench, tmp_path):
    if subprocess.run(["git", "-C", str(REPO), "rev-parse", "HEAD"], capture_output=True).returncode:
        pytest.skip("not a git checkout")
    bench.export_build("HEAD", tmp_path)
    trainer = tmp_path / "selfplaydrive" / "trainers" / "ppo" / "trainer.py"
    assert trainer.is_file() and (tmp_path / "selfplaydrive" / "models" / "deepsets.py").is_file()
    assert not (tmp_path / "selfplaydrive" / "sim").exists()  # the simulator stays this tree's
    overlay = bench._Overlay(tmp_path)
    assert Path(overlay.find_spec("selfplaydrive.trainers.ppo.trainer").origin) == trainer
    package = overlay.find_spec("selfplaydrive.models")
    assert package.submodule_search_locations == [str(tmp_path / "selfplaydrive" / "models")]
    assert overlay.find_spec("selfplaydrive.sim.vec_env") is None
    assert overlay.find_spec("selfplaydrive.trainers.callbacks") is None


def test_overlay_imports_the_exported_code_in_a_fresh_process(bench, tmp_path):
    if subprocess.run(["git", "-C", str(REPO), "rev-parse", "HEAD"], capture_output=True).returncode:
        pytest.skip("not a git checkout")
    bench.export_build("HEAD", tmp_path)
    marker = tmp_path / "selfplaydrive" / "models" / "common.py"
    marker.write_text(marker.read_text() + "\nBASELINE_MARKER = 1\n")
    code = (
        f"import sys; sys.path.insert(0, {str(REPO / 'benchmarks')!r}); import bench_train; "
        f"from pathlib import Path; sys.meta_path.insert(0, bench_train._Overlay(Path({str(tmp_path)!r}))); "
        "import selfplaydrive.models.common as c; print(c.BASELINE_MARKER, c.__file__)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["1", str(marker)]


def test_summary_takes_medians_and_phase_shares(bench):
    updates = [
        {
            "acting_speed": 1.0,
            "agent_steps": 100,
            "wall_s": 1.0,
            "cpu_s": 2.0,
            "collect_s": 0.5,
            "env_step": 0.1,
            "policy": 0.4,
            "advantages": 0.0,
            "update": 0.5,
        },
        {
            "acting_speed": 3.0,
            "agent_steps": 300,
            "wall_s": 1.0,
            "cpu_s": 1.0,
            "collect_s": 0.5,
            "env_step": 0.2,
            "policy": 0.3,
            "advantages": 0.1,
            "update": 0.4,
        },
        {
            "acting_speed": 0.5,
            "agent_steps": 1000,
            "wall_s": 2.0,
            "cpu_s": 2.0,
            "collect_s": 1.0,
            "env_step": 0.2,
            "policy": 0.8,
            "advantages": 0.0,
            "update": 1.0,
        },
    ]
    out = bench.summarize(updates, slots=1000)
    assert out["agent_steps_per_s"] == 300  # rates 100, 300, 500
    assert out["slot_steps_per_s"] == 1000  # 1000 slot-steps in 1, 1, 2 s: 1000, 1000, 500
    assert out["acting_share"] == pytest.approx(0.3)  # 0.1, 0.3, 1.0
    assert out["acting_speed"] == 1.0  # 1.0, 3.0, 0.5
    assert out["agent_steps_per_cpu_s"] == 300  # 50, 300, 500
    assert out["collect_agent_steps_per_s"] == 600  # 200, 600, 1000
    assert out["share_env_step"] == pytest.approx(0.1)  # 0.1, 0.2, 0.1
    assert out["share_update"] == pytest.approx(0.5)  # 0.5, 0.4, 0.5


def test_overlay_of_a_build_older_than_this_trees_run_module(bench, tmp_path):
    """A baseline whose trainer package lacks a name this tree's trainers/run.py imports (as
    743fc18~1 lacks `dist.check_resume_agrees`) still gets its own trainer and model."""
    if subprocess.run(["git", "-C", str(REPO), "rev-parse", "HEAD"], capture_output=True).returncode:
        pytest.skip("not a git checkout")
    bench.export_build("HEAD", tmp_path)
    dist = tmp_path / "selfplaydrive" / "trainers" / "ppo" / "dist.py"
    dist.write_text(dist.read_text().replace("def check_resume_agrees(", "def _renamed_in_this_build("))
    code = (
        f"import sys; sys.path.insert(0, {str(REPO / 'benchmarks')!r}); import bench_train; "
        f"seed = bench_train.install_overlay({str(tmp_path)!r}); seed(0); "
        "import selfplaydrive.trainers.ppo.trainer as t, selfplaydrive.models.deepsets as d; "
        "print(t.__file__, d.__file__)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == [
        str(tmp_path / "selfplaydrive" / "trainers" / "ppo" / "trainer.py"),
        str(tmp_path / "selfplaydrive" / "models" / "deepsets.py"),
    ]


def test_init_from_starts_both_builds_from_the_shipped_weights(bench):
    """`--init-from pretrained`: both workers (here this tree twice, one with other overrides)
    start from the shipped policy's weights, and the summary reports slot-steps and acting
    shares. The digests come from the workers' own models after loading."""
    from selfplaydrive.policies import load_checkpoint
    from selfplaydrive.pretrained import resolve_spec

    shipped = bench.weights_digest(load_checkpoint(resolve_spec("pretrained"))["model"])
    overrides = [
        "model=deepsets_laptop",
        "reward=paper",
        "obs.max_objects=32",  # the shipped policy's layout
        "spawner.num_agents=8",
        "env.num_worlds=1",
        "trainer.rollout_length=4",
        "trainer.num_minibatches=1",
        "trainer.overlap_collection=false",
        "trainer.learning_rate=1e-12",
    ]
    result = bench.run(overrides, 1, None, ["trainer.num_epochs=1"], init_from="pretrained")
    for key in ("current", "baseline"):
        r = result[key]
        assert r["init_from"] == "pretrained" and r["initial_weights"] == shipped
        assert r["slots_per_update"] == 4 * 8
        assert 0.0 < r["acting_share"] <= 1.0
        assert r["slot_steps_per_s"] >= r["agent_steps_per_s"] > 0
    assert result["slot_ratio_of_medians"] > 0


def test_acting_speed_is_the_mean_over_the_acting_agents(bench):
    """Hand-computed: agents at 10 and 20 m/s act, one at 30 m/s does not."""
    import numpy as np

    class Env:
        masks = np.array([True, False, True])
        buffers = {"speed": np.array([[10.0, 30.0, 20.0]])}  # (W, A) like the env's

    assert bench.acting_speed(Env()) == 15.0
    Env.masks = np.zeros(3, dtype=bool)
    assert bench.acting_speed(Env()) == 0.0


def test_init_from_initial_gives_the_baseline_this_trees_starting_weights(bench):
    """`--init-from initial`: this tree's worker writes the weights it starts from and the
    baseline's worker (here this tree with a different seed, which would start elsewhere)
    loads them."""
    import torch

    from selfplaydrive.trainers.run import seed_everything

    overrides = [
        "spawner.num_agents=8",
        "env.num_worlds=1",
        "trainer.rollout_length=4",
        "trainer.num_minibatches=1",
        "trainer.overlap_collection=false",
    ]
    threads = torch.get_num_threads()  # build_trainer sets the config's count in this process
    try:
        trainer, _ = bench.build_trainer([*overrides, "seed=1"], seed_everything)
    finally:
        torch.set_num_threads(threads)
    alone = bench.weights_digest(trainer.model.state_dict())  # where seed 1 starts by itself
    result = bench.run(overrides, 1, None, ["seed=1"], init_from="initial")
    cur, base = result["current"], result["baseline"]
    assert cur["initial_weights"] == base["initial_weights"] != alone
    assert cur["init_from"] is None and base["init_from"].endswith("initial.pt")
    assert cur["acting_speed"] >= 0.0 and base["acting_speed"] >= 0.0
