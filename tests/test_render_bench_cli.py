"""`selfplaydrive render` and `selfplaydrive bench` take Hydra overrides and `-m` like train and
eval: the env comes from the config groups, every run folder gets its config and metadata,
and bad arguments fail with the valid choices."""

from __future__ import annotations

import json
import warnings
from importlib import resources

from PIL import Image

from selfplaydrive.cli import main

DEFAULT_NPZ = resources.files("selfplaydrive").parent / "maps" / "default_town.npz"
QUICK_BENCH = ["env.num_worlds=1", "steps=2", "warmup=0", "repeats=1", "threads=[1]"]


def test_render_sweep_writes_one_file_per_run(tmp_path, capsys):
    argv = [
        "render",
        "-m",
        "seed=0,1",
        "physics=bicycle",
        "steps=1",
        "size=64",
        "output=${hydra:runtime.output_dir}/ep.gif",
        f"hydra.sweep.dir={tmp_path}",
    ]
    assert main(argv) == 0
    for job, seed in ((0, 0), (1, 1)):
        with Image.open(tmp_path / str(job) / "ep.gif") as im:
            assert im.n_frames == 2 and im.size == (64, 64)
        meta = json.loads((tmp_path / str(job) / "run_meta.json").read_text())
        assert meta["seed"] == seed and meta["choices"]["physics"] == "bicycle"
    assert capsys.readouterr().out.count("wrote 2 frames") == 2


def test_render_errors_name_the_key(tmp_path, capsys):
    run = f"hydra.run.dir={tmp_path}"
    assert main(["render", "world=1", "steps=1", f"output={tmp_path / 'a.gif'}", run]) == 2
    assert "env.num_worlds" in capsys.readouterr().err
    assert main(["render", "drivr=random", run]) == 1
    assert "valid keys under '<root>':" in capsys.readouterr().err
    assert main(["render", "physics=nope", run]) == 1
    assert (
        "valid options for 'physics': bicycle, custom, delta, friction, jerk, pymunk"
        in capsys.readouterr().err
    )
    assert main(["render", "--driver", "random", run]) == 2  # the old argparse flags
    assert "unrecognized argument(s) --driver" in capsys.readouterr().err


def test_bench_json_on_a_map_file(tmp_path, capsys):
    argv = ["bench", "json=true", "map=file", f"map.spec={DEFAULT_NPZ}", *QUICK_BENCH]
    assert main([*argv, f"hydra.run.dir={tmp_path}"]) == 0
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert out["map"] == str(DEFAULT_NPZ) and out["num_agents"] == 32
    assert [r["threads"] for r in out["results"]] == [1]
    assert set(out["stage_ms_per_step"]["1"]) >= {"physics", "observation", "reset"}
    assert json.loads((tmp_path / "bench.json").read_text()) == out
    assert json.loads((tmp_path / "run_meta.json").read_text())["choices"]["map"] == "file"


def test_bench_sweep_over_config_groups(tmp_path, capsys):
    argv = ["bench", "-m", "physics=bicycle,friction", "spawner.num_agents=8", "stages=false", "--json"]
    assert main([*argv, *QUICK_BENCH, f"hydra.sweep.dir={tmp_path}"]) == 0
    for job, physics in ((0, "bicycle"), (1, "friction")):
        out = json.loads((tmp_path / str(job) / "bench.json").read_text())
        assert out["num_agents"] == 8 and out["stage_ms_per_step"] == {}
        config = (tmp_path / str(job) / "resolved_config.yaml").read_text()
        assert {"bicycle": "BicycleModel", "friction": "FrictionBicycleModel"}[physics] in config
    assert main(["bench", "--worlds", "2"]) == 2
    assert "unrecognized argument(s) --worlds" in capsys.readouterr().err
    assert main(["bench", "threads=[]", *QUICK_BENCH[:-1], f"hydra.run.dir={tmp_path}"]) == 2
    assert "threads" in capsys.readouterr().err


def test_bench_counts_spawn_shortfalls_instead_of_warning(tmp_path, capsys):
    # 60 m between agents cannot be met for 32 agents in a 200 m region: every world falls short
    argv = ["bench", "json=true", "spawner.min_agent_distance=60", *QUICK_BENCH, f"hydra.run.dir={tmp_path}"]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert main(argv) == 0
    captured = capsys.readouterr()
    assert not [w for w in caught if "PaperSpawner placed" in str(w.message)]
    assert "PaperSpawner" not in captured.err
    short = json.loads(captured.out.strip().splitlines()[-1])["spawn_shortfall"]
    assert short["worlds"] >= 1 and short["missing_agents"] >= short["worlds"]
