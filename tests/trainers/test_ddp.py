"""Data parallelism through torchrun + torch.distributed (Gloo on the CPU), issue #5 item 3."""

import subprocess
import sys
from pathlib import Path

import torch


def test_two_ranks_keep_identical_parameters_on_different_data(tmp_path):
    worker = Path(__file__).resolve().parent / "ddp_worker.py"
    cmd = [
        sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node=2",
        str(worker), str(tmp_path),
    ]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
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
