"""Under torchrun every rank writes one run folder, named by torchrun's run id (the default
time-stamp folder differs between nodes whose processes start in different seconds)."""

from __future__ import annotations

from selfplaydrive.hydra_app import torchrun_run_dir

RANK1 = {"TORCHELASTIC_RUN_ID": "job42", "WORLD_SIZE": "2", "RANK": "1"}


def test_ranks_share_the_folder_of_the_run_id() -> None:
    argv = ["seed=3"]
    rank0 = torchrun_run_dir(argv, dict(RANK1, RANK="0"))
    assert rank0 == torchrun_run_dir(argv, RANK1) == ["seed=3", "hydra.run.dir=outputs/train/torchrun-job42"]


def test_an_explicit_folder_a_sweep_or_one_process_is_left_alone() -> None:
    assert torchrun_run_dir(["hydra.run.dir=/x"], RANK1) == ["hydra.run.dir=/x"]
    assert torchrun_run_dir(["-m", "seed=1,2"], RANK1) == ["-m", "seed=1,2"]
    assert torchrun_run_dir(["seed=1"], {"TORCHELASTIC_RUN_ID": "j", "WORLD_SIZE": "1"}) == ["seed=1"]
    assert torchrun_run_dir(["seed=1"], {}) == ["seed=1"]
