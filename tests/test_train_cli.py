"""`selfplaydrive train` end to end on the bundled town, a few tiny updates per run:
same seed -> same metrics and parameters; `resume=` continues a run exactly, without
duplicate metric rows; the evaluation names its protocol."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

torch = pytest.importorskip("torch")

from selfplaydrive.cli import main  # noqa: E402
from selfplaydrive.eval.collisions import KINDS  # noqa: E402
from selfplaydrive.trainers.ppo.logging import WALL_CLOCK_TAGS  # noqa: E402

# 1 world x 32 agent slots x 8 steps = 256 slot-steps per update; no lr annealing, so the first
# updates of a long run equal those of a short one (the resume comparison needs that)
UPDATE = 256
TINY = [
    "env.num_worlds=1",
    "spawner.num_agents=32",
    "trainer.rollout_length=8",
    "trainer.anneal_lr=false",
    "trainer.checkpoint_interval=1",
    "trainer.keep_checkpoints=10",
    "trainer.eval_episodes=1",
    "trainer.eval_max_steps=20",
    "trainer.progress_bar=false",
    "logger=jsonl",
]


def train(out: Path, updates: int, *extra: str) -> Path:
    code = main(["train", *TINY, f"trainer.total_steps={updates * UPDATE}", f"hydra.run.dir={out}", *extra])
    assert code == 0
    return out


def rows(run: Path) -> list[dict[str, float]]:
    """metrics.jsonl without the wall-clock fields (throughput and the line's time stamp)."""
    lines = (run / "metrics.jsonl").read_text().splitlines()
    return [{k: v for k, v in json.loads(line).items() if k not in WALL_CLOCK_TAGS} for line in lines]


def params(run: Path) -> dict[str, torch.Tensor]:
    return torch.load(run / "checkpoints" / "final.pt", weights_only=False)["model"]


def assert_same_params(a: dict[str, torch.Tensor], b: dict[str, torch.Tensor]) -> None:
    assert a.keys() == b.keys()
    for name in a:
        assert torch.equal(a[name], b[name]), name


def test_same_seed_same_run_and_another_seed_differs(tmp_path):
    a = train(tmp_path / "a", 2, "seed=3")
    b = train(tmp_path / "b", 2, "seed=3")  # same process: torch's global generator has moved on
    c = train(tmp_path / "c", 2, "seed=4")
    assert len(rows(a)) == 2 and [r["step"] for r in rows(a)] == [UPDATE, 2 * UPDATE]
    assert rows(a) == rows(b)
    assert_same_params(params(a), params(b))
    # the initial weights follow the seed too: another seed gives other parameters
    assert any(not torch.equal(p, params(c)[k]) for k, p in params(a).items())
    # the main job trains under the fixed evaluation coefficients (reward=eval): one evaluation,
    # which names that protocol
    summary = json.loads((a / "eval.json").read_text())
    assert summary["protocol"] == "fixed_eval_coefficients" and summary["actions"] == "sampled"
    assert "fixed_eval_coefficients" not in summary and "agent_episodes" in summary
    # with its vehicle collisions by kind (eval.collisions)
    kinds = summary["collision_kinds"]
    assert sum(kinds[k]["count"] for k in KINDS) == kinds["collisions"]


def test_a_conditioned_run_is_evaluated_under_both_protocols_unless_asked_not_to(tmp_path):
    # reward=paper draws the coefficients per agent (section 2.3): evaluated under that
    # distribution, then from the same seed under the paper's protocol
    summary = json.loads((train(tmp_path / "paper", 1, "reward=paper") / "eval.json").read_text())
    assert summary["protocol"] == "training_distribution" and summary["actions"] == "sampled"
    fixed = summary["fixed_eval_coefficients"]
    assert fixed["protocol"] == "fixed_eval_coefficients" and fixed["actions"] == "sampled"
    assert "agent_episodes" in fixed and "collision_kinds" in fixed
    off = train(tmp_path / "off", 1, "reward=paper", "trainer.eval_fixed_coefficients=false")
    assert "fixed_eval_coefficients" not in json.loads((off / "eval.json").read_text())
    # fixed coefficients with a curriculum on: the training worlds are not the protocol's either
    curriculum = train(tmp_path / "curriculum", 1, "spawner.turn_lane_worlds=0.5")
    summary = json.loads((curriculum / "eval.json").read_text())
    assert summary["protocol"] == "training_distribution"
    assert summary["fixed_eval_coefficients"]["protocol"] == "fixed_eval_coefficients"


def test_resume_from_folder_and_checkpoint_matches_an_uninterrupted_run(tmp_path):
    full = train(tmp_path / "full", 4, "seed=1")
    run = train(tmp_path / "run", 2, "seed=1")
    # a killed checkpoint writer leaves a .tmp behind; the resume removes it
    stale = run / "checkpoints" / "ckpt_0000003.pt.tmp"
    stale.write_bytes(b"half a checkpoint")
    # from the run folder (its newest checkpoint, update 2) to update 3, in the same folder
    train(tmp_path / "resume1", 3, "seed=1", f"resume={run}")
    assert not stale.exists()
    assert [r["step"] for r in rows(run)] == [UPDATE * k for k in (1, 2, 3)]
    note = json.loads((tmp_path / "resume1" / "resume.json").read_text())
    assert note["update"] == 2 and Path(note["run_folder"]) == run
    # from an older checkpoint file: the rows after it (update 3) are dropped, then rewritten
    train(tmp_path / "resume2", 4, "seed=1", f"resume={run / 'checkpoints' / 'ckpt_0000002.pt'}")
    steps = [r["step"] for r in rows(run)]
    assert steps == [UPDATE * k for k in (1, 2, 3, 4)], "duplicate or missing rows after a resume"
    assert rows(run) == rows(full)
    assert_same_params(params(run), params(full))
    assert len((run / "resumes.jsonl").read_text().splitlines()) == 2


def test_resume_of_a_missing_folder_fails_with_one_line_naming_it(tmp_path, capsys):
    where = tmp_path / "nowhere"
    code = main(["train", *TINY, f"hydra.run.dir={tmp_path / 'x'}", f"resume={where}"])
    err = capsys.readouterr().err.strip()
    assert code == 1
    assert err.startswith("selfplaydrive train: error:") and "\n" not in err
    assert str(where) in err and "no such file or folder" in err


def test_init_from_starts_a_new_run_from_a_checkpoints_weights(tmp_path):
    """`init_from=` takes only the weights: the new run starts at update 0 in its own folder, and
    after one update its parameters sit far closer to the source's than a fresh run's do."""
    source = train(tmp_path / "source", 2)
    tuned = train(tmp_path / "tuned", 1, f"init_from={source / 'checkpoints' / 'final.pt'}", "seed=5")
    fresh = train(tmp_path / "fresh", 1, "seed=5")
    assert len(rows(tuned)) == 1 and not (tuned / "resumes.jsonl").exists()
    src, a, b = params(source), params(tuned), params(fresh)
    near = sum(float((a[k] - src[k]).abs().sum()) for k in src)
    far = sum(float((b[k] - src[k]).abs().sum()) for k in src)
    assert near < 0.2 * far


def test_init_widen_starts_the_papers_sizes_from_the_shipped_laptop_policy(tmp_path):
    """`model=deepsets init_from=pretrained init_widen=true`: the shipped 32 / 128 / 128 policy
    copied into 64 / 256 / 256 trains; its first update starts from the shipped function (the
    widened weights' copies add up to the shipped ones)."""
    from selfplaydrive import pretrained
    from selfplaydrive.policies import load_checkpoint

    # a tiny learning rate: Adam moves each weight by at most ~lr per minibatch step
    extra = ("model=deepsets", "init_from=pretrained", "init_widen=true", "trainer.learning_rate=1e-5")
    run = train(tmp_path / "wide", 1, *extra)
    wide, shipped = params(run), load_checkpoint(pretrained.checkpoint_path())["model"]
    assert wide["actor.weight"].shape == (20, 256) and shipped["actor.weight"].shape == (20, 128)
    summed = wide["actor.weight"][:, :128] + wide["actor.weight"][:, 128:]
    assert float((summed - shipped["actor.weight"]).abs().max()) < 1e-3  # one small update away


@pytest.mark.parametrize(
    ("extra", "expected"),
    [
        (["init_from=pretrained", "model=deepsets"], "do not fit this run's DeepSetsModel"),
        (["init_from=pretrained", "model=transformer", "init_widen=true"], "init_widen needs model=deepsets"),
        (["init_from=pretrained", "model=deepsets_small", "init_widen=true"], "cannot widen input_size"),
        (["init_from=pretrained", "resume=somewhere"], "init_from and resume both set"),
        (["init_widen=true"], "init_widen=true needs init_from"),
    ],
)
def test_init_from_refuses_foreign_weights_and_resume_in_one_line(tmp_path, capsys, extra, expected):
    code = main(["train", *TINY, f"hydra.run.dir={tmp_path / 'x'}", *extra])
    err = capsys.readouterr().err.strip()
    assert code == 1
    assert err.startswith("selfplaydrive train: error:") and "\n" not in err
    assert expected in err
