"""Checkpoint loading refuses what it did not write, with one line naming the file; stale
`.tmp` files of a killed writer are removed; resume picks the furthest checkpoint."""

from __future__ import annotations

import pickle
from pathlib import Path

import pytest
import torch

from selfplaydrive.errors import CheckpointError
from selfplaydrive.trainers.ppo import checkpoint as ckpt


class Boom:
    """Unpickling it would create a file: a stand-in for code a foreign .pt could run."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (Path.touch, (self.marker,))


def refused(path: Path, match: str) -> str:
    with pytest.raises(CheckpointError, match=match) as info:
        ckpt.load(path)
    message = str(info.value)
    assert str(path) in message and "\n" not in message
    return message


def test_missing_file(tmp_path):
    refused(tmp_path / "none.pt", "no such file")


def test_garbage_and_empty_files(tmp_path):
    (tmp_path / "garbage.pt").write_bytes(b"this is not a checkpoint at all")
    refused(tmp_path / "garbage.pt", "not a torch checkpoint file")
    (tmp_path / "empty.pt").write_bytes(b"")
    refused(tmp_path / "empty.pt", "empty or cut short")


def test_foreign_dict_names_the_missing_keys(tmp_path):
    torch.save({"state_dict": {"w": torch.zeros(2)}}, tmp_path / "foreign.pt")
    message = refused(tmp_path / "foreign.pt", "not a selfplaydrive checkpoint")
    assert "'model'" in message and "'env'" in message


def test_pickled_object_is_refused_without_running_code(tmp_path):
    marker = tmp_path / "ran"
    torch.save({"model": Boom(marker)}, tmp_path / "evil.pt")
    refused(tmp_path / "evil.pt", "it refers to .*never contains")
    assert not marker.exists()
    with (tmp_path / "plain.pkl").open("wb") as f:  # a plain pickle, not torch's zip format
        pickle.dump(Boom(marker), f)
    refused(tmp_path / "plain.pkl", "cannot read the checkpoint")
    assert not marker.exists()


def test_other_format_version(tmp_path):
    payload = {"format_version": 99, "model": {}, "optimizer": {}, "counters": {}, "env": {}}
    torch.save(payload, tmp_path / "v99.pt")
    refused(tmp_path / "v99.pt", r"format_version 99, expected one of \(1, 2\)")


def test_save_removes_only_its_own_ranks_stale_tmp_files(tmp_path):
    stale0, stale1 = tmp_path / "ckpt_0000004.pt.tmp", tmp_path / "ckpt_0000004.rank1.pt.tmp"
    stale0.write_bytes(b"x")
    stale1.write_bytes(b"x")
    path = ckpt.save(tmp_path / "ckpt_0000005.pt", {"model": {}, "optimizer": {}, "counters": {}, "env": {}})
    assert path.is_file() and not stale0.exists() and stale1.exists()
    assert ckpt.load(path)["format_version"] == ckpt.FORMAT_VERSION
    assert ckpt.remove_stale_tmp(tmp_path, rank=1) == [stale1]


def test_newest_prefers_the_checkpoint_furthest_into_training(tmp_path):
    def write(name: str, update: int) -> Path:
        payload = {"model": {}, "optimizer": {}, "counters": {"update": update}, "env": {}}
        return ckpt.save(tmp_path / name, payload)

    assert ckpt.newest(tmp_path) is None
    write(ckpt.checkpoint_name(4), 4)
    final = write(ckpt.final_name(), 4)
    assert ckpt.newest(tmp_path) == final  # as far as the periodic one: the final state
    later = write(ckpt.checkpoint_name(6), 6)  # a resumed run stopped before its end
    assert ckpt.newest(tmp_path) == later
    assert ckpt.rank_name("ckpt_0000006.pt", 2) == "ckpt_0000006.rank2.pt"
    assert ckpt.rank_name("final.rank2.pt", 0) == "final.pt"
