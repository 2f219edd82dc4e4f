"""Data parallelism through torchrun + torch.distributed (Gloo on the CPU), issue #5 item 3."""

import subprocess
import sys
from pathlib import Path

import torch

WORKER = Path(__file__).resolve().parent / "ddp_worker.py"


def run_two_ranks(*args: str) -> None:
    """`ddp_worker.py *args` on two CPU ranks under torchrun; fail with its output."""
    cmd = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node=2", str(WORKER)]
    done = subprocess.run([*cmd, *args], capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]


def test_two_ranks_keep_identical_parameters_on_different_data(tmp_path):
    run_two_ranks(str(tmp_path))
    r0, r1 = (torch.load(tmp_path / f"rank{r}.pt", weights_only=False) for r in (0, 1))
    assert (r0["rank"], r1["rank"], r0["world_size"]) == (0, 1, 2)
    # each rank stepped its own env (seed + rank): different data
    assert not torch.equal(r0["first_obs"], r1["first_obs"])
    # the ranks were initialised differently; DDP broadcast rank 0's parameters, and the
    # averaged gradients kept them identical through two updates that changed them
    assert any(not torch.equal(r0["start"][k], r1["start"][k]) for k in r0["start"])
    for k in r0["end"]:
        assert torch.equal(r0["end"][k], r1["end"][k]), k
    assert any(not torch.equal(r0["start"][k], r0["end"][k]) for k in r0["end"])
    # asked for update_threads=2, each rank trained on one thread and said why
    for r in (r0, r1):
        assert r["update_threads"] == 1
        said = "trainer.update_threads = 2 is 1 under torchrun"
        assert any(said in w for w in r["warnings"]), r["warnings"]


def test_a_resume_whose_ranks_find_different_updates_fails_on_every_rank(tmp_path):
    # rank 1's newest checkpoint is of update 1, rank 0's of update 2: resumed anyway, the ranks
    # would train from different parameters and update counts (it did, before the check)
    run_two_ranks("--resume-mismatch", str(tmp_path))
    for r in (0, 1):
        error = (tmp_path / f"error.rank{r}.txt").read_text()
        assert "rank 0 update 2, rank 1 update 1" in error, error
        assert "checkpoints/ckpt_0000001.pt" in error, error
    # nothing trained past the checkpoints
    assert not (tmp_path / "run" / "checkpoints" / "ckpt_0000003.pt").exists()
