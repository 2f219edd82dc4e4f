"""Data parallelism across machines (issue #16 item 5): two torchrun "nodes" on this machine.

Each node is its own `torchrun --nnodes=2 --nproc_per_node=1 --rdzv-backend=c10d` process
running the real CLI (`-m selfplaydrive.cli train`) with one rank on the CPU (Gloo); the two
meet at a c10d rendezvous on 127.0.0.1 and share one run folder, as nodes of a cluster share
a file system. One uninterrupted four-update run, then a copy of its folder cut back to the
update-2 checkpoints (a job killed after them) resumed to four updates on both nodes.
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from selfplaydrive.builder import build_env, compose  # noqa: E402
from selfplaydrive.trainers.ppo.logging import WALL_CLOCK_TAGS  # noqa: E402

HERE = Path(__file__).resolve().parent
SEED = 5  # rank r's env is seeded SEED + r: not to be confused with r itself
RANKS = (0, 1)
# per rank: 1 world x 32 agent slots x 8 steps = 256 slot-steps per update; no lr annealing
UPDATE = 256
TINY = [
    "env.num_worlds=1",
    "spawner.num_agents=32",
    "trainer.rollout_length=8",
    "trainer.anneal_lr=false",
    "trainer.torch_threads=1",
    "trainer.checkpoint_interval=1",
    "trainer.keep_checkpoints=10",
    "trainer.eval_episodes=0",
    "trainer.progress_bar=false",
    "logger=jsonl",
    f"seed={SEED}",
]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def node_command(node: int, port: int, job: str, overrides: list[str]) -> list[str]:
    """What node `node` of the two runs (`--node-rank` is informational under c10d, which
    numbers the nodes itself)."""
    return [
        sys.executable, "-m", "torch.distributed.run", "--nnodes=2", "--nproc_per_node=1",
        f"--node-rank={node}", "--rdzv-backend=c10d", f"--rdzv-endpoint=127.0.0.1:{port}",
        f"--rdzv-id={job}", "-m", "selfplaydrive.cli", "train", *overrides,
    ]  # fmt: skip


def train_two_nodes(invoked_in: Path, updates: int, *extra: str) -> None:
    """Start both nodes of a CLI training run and wait for them; fail with their output."""
    record = f"trainer.callbacks=[{{_target_:ddp_worker.FirstObservations,out:'{invoked_in / 'first'}'}}]"
    budget = f"trainer.total_steps={updates * UPDATE}"
    overrides = [*TINY, record, budget, f"hydra.run.dir={invoked_in}", *extra]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(HERE), os.environ.get("PYTHONPATH", "")]))
    env.update(OMP_NUM_THREADS="1", HYDRA_FULL_ERROR="1")
    port = free_port()
    nodes = [
        subprocess.Popen(
            node_command(n, port, invoked_in.name, overrides),
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        for n in RANKS
    ]
    try:
        logs = [node.communicate(timeout=240)[0] for node in nodes]
    finally:
        for node in nodes:
            node.kill()  # a no-op for a node that ended
    codes = [node.returncode for node in nodes]
    assert codes == [0, 0], "\n".join(log[-3000:] for log in logs)


def checkpoint(run: Path, name: str, rank: int) -> dict[str, object]:
    suffix = ".pt" if rank == 0 else f".rank{rank}.pt"
    return torch.load(run / "checkpoints" / f"{name}{suffix}", weights_only=False)


def rows(run: Path) -> list[dict[str, float]]:
    """metrics.jsonl (rank 0's) without the wall-clock fields."""
    lines = (run / "metrics.jsonl").read_text().splitlines()
    return [{k: v for k, v in json.loads(line).items() if k not in WALL_CLOCK_TAGS} for line in lines]


def assert_same_params(a: dict[str, torch.Tensor], b: dict[str, torch.Tensor]) -> None:
    assert a.keys() == b.keys()
    for name in a:
        assert torch.equal(a[name], b[name]), name


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    """The uninterrupted four-update run and the run resumed from its update-2 checkpoints."""
    root = tmp_path_factory.mktemp("multinode")
    full = root / "full"
    train_two_nodes(full, 4)
    part = root / "part"
    shutil.copytree(full, part, ignore=shutil.ignore_patterns("ckpt_000000[34]*", "final*", "first"))
    train_two_nodes(root / "resume", 4, f"resume={part}")
    return {"full": full, "part": part, "resume": root / "resume"}


def test_each_rank_steps_worlds_seeded_seed_plus_rank(runs):
    files = {r: runs["full"] / "first" / f"first_obs.rank{r}.pt" for r in RANKS}
    first = {r: torch.load(f, weights_only=False) for r, f in files.items()}
    assert [first[r]["env_seed"] for r in RANKS] == [SEED, SEED + 1]
    assert not torch.equal(first[0]["obs"], first[1]["obs"])
    # the same observations as this process's env of the same config reset with SEED + rank
    env = build_env(compose("train", TINY))
    for r in RANKS:
        env.reset(seed=SEED + r)
        assert torch.equal(first[r]["obs"], torch.from_numpy(env.observations.copy())), r
    # and the ranks' worlds stay apart: their env states differ after four updates
    envs = [checkpoint(runs["full"], "final", r)["env"] for r in RANKS]  # VecEnv.get_state()
    buffers = [k for k in envs[0] if k.startswith("buffers.")]
    assert buffers and any(not np.array_equal(envs[0][k], envs[1][k]) for k in buffers)


def test_parameters_end_identical_on_both_nodes(runs):
    ends = [checkpoint(runs["full"], "final", r)["model"] for r in RANKS]
    assert_same_params(ends[0], ends[1])
    # ... after updates that changed them
    start = checkpoint(runs["full"], "ckpt_0000001", 0)["model"]
    assert any(not torch.equal(start[k], ends[0][k]) for k in start)


def test_resumed_two_node_run_continues_exactly(runs):
    full, part = runs["full"], runs["part"]
    for r in RANKS:
        assert checkpoint(part, "final", r)["counters"]["update"] == 4
        assert_same_params(checkpoint(part, "final", r)["model"], checkpoint(full, "final", r)["model"])
    assert [row["step"] for row in rows(part)] == [2 * UPDATE * k for k in (1, 2, 3, 4)]
    assert rows(part) == rows(full)
    note = json.loads((runs["resume"] / "resume.json").read_text())
    assert note["update"] == 2 and Path(note["run_folder"]) == part
