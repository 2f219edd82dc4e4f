"""`trainers.soup`: the mean of fine-tuned weights, checked by hand and on the shipped policy."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

torch = pytest.importorskip("torch")

from selfplaydrive import pretrained  # noqa: E402
from selfplaydrive.errors import CheckpointError  # noqa: E402
from selfplaydrive.trainers import soup  # noqa: E402


def test_average_weights_hand_computed():
    """(1, 2) and (3, 6) average to (2, 4); float16 stays float16; equal integer tensors pass."""
    a = {"w": torch.tensor([1.0, 2.0]), "h": torch.tensor([1.0], dtype=torch.float16), "n": torch.tensor([7])}
    b = {"w": torch.tensor([3.0, 6.0]), "h": torch.tensor([2.0], dtype=torch.float16), "n": torch.tensor([7])}
    out = soup.average_weights([a, b], ["a.pt", "b.pt"])
    assert out["w"].tolist() == [2.0, 4.0]
    assert out["h"].dtype == torch.float16 and out["h"].item() == 1.5
    assert out["n"].tolist() == [7]


def test_average_weights_refuses_what_does_not_fit():
    a = {"w": torch.zeros(2), "n": torch.tensor([7])}
    with pytest.raises(ValueError, match="at least two"):
        soup.average_weights([a], ["a.pt"])
    with pytest.raises(ValueError, match=r"b.pt: weight 'w' is \(3,\) torch.float32, expected \(2,\)"):
        soup.average_weights([a, {"w": torch.zeros(3), "n": torch.tensor([7])}], ["a.pt", "b.pt"])
    with pytest.raises(ValueError, match=r"b.pt: weights \['v'\] not in a.pt, \['w'\] missing"):
        soup.average_weights([a, {"v": torch.zeros(2), "n": torch.tensor([7])}], ["a.pt", "b.pt"])
    with pytest.raises(ValueError, match="integer tensor 'n' differs"):
        soup.average_weights([a, {"w": torch.zeros(2), "n": torch.tensor([8])}], ["a.pt", "b.pt"])


def _run(folder: Path, shift: float) -> Path:
    """A run folder holding the shipped policy's weights plus `shift` and its run config."""
    (folder / "checkpoints").mkdir(parents=True)
    shutil.copy(pretrained.FOLDER / pretrained.RUN_CONFIG, folder / "resolved_config.yaml")
    payload = torch.load(pretrained.checkpoint_path(), map_location="cpu", weights_only=False)
    payload["model"] = {k: v + shift if v.is_floating_point() else v for k, v in payload["model"].items()}
    path = folder / "checkpoints" / "final.pt"
    torch.save(payload, path)
    return path


def test_soup_of_runs_is_their_mean_and_drives(tmp_path):
    """The shipped weights shifted by 0 and by 0.5 give the weights shifted by 0.25; the soup
    folder is a run that `make_policy` drives and `pretrained.ship` ships."""
    from selfplaydrive.policies import make_policy
    from selfplaydrive.pretrained.ship import ship

    a, b = _run(tmp_path / "a", 0.0), _run(tmp_path / "b", 0.5)
    meta = soup.make_soup([a, b], tmp_path / "soup")
    assert [i["checkpoint"] for i in meta["ingredients"]] == [str(a), str(b)]
    made = torch.load(tmp_path / "soup" / "checkpoints" / "final.pt", weights_only=False)["model"]
    ref = torch.load(a, weights_only=False)["model"]
    for key, value in ref.items():
        assert torch.allclose(made[key], value + 0.25, atol=1e-6), key
    assert json.loads((tmp_path / "soup" / "soup.json").read_text())["sha256"] == meta["sha256"]

    env = pretrained.build_env(num_worlds=1, seed=0)
    obs = env.reset(seed=1)
    actions = make_policy(str(tmp_path / "soup" / "checkpoints" / "final.pt"), env)(obs, env)
    assert actions.shape == (env.num_agents, 2) and (actions >= 0).all()
    shipped = ship(tmp_path / "soup" / "checkpoints" / "final.pt", {"command": "soup"}, tmp_path / "ship")
    assert shipped["layout"] == pretrained.layout_signature(env) and shipped["update"] is None

    with pytest.raises(FileExistsError, match="new folder"):
        soup.make_soup([a, b], tmp_path / "soup")
    with pytest.raises(ValueError, match="named twice"):
        soup.make_soup([a, a], tmp_path / "again")


def test_soup_refuses_other_layouts_and_foreign_files(tmp_path):
    a, b = _run(tmp_path / "a", 0.0), _run(tmp_path / "b", 0.1)
    cfg = tmp_path / "b" / "resolved_config.yaml"
    cfg.write_text(cfg.read_text().replace("max_road: 64", "max_road: 65"))
    with pytest.raises(ValueError, match=r"node 'obs' is .*'max_road': 65.*expected .*'max_road': 64"):
        soup.make_soup([a, b], tmp_path / "soup")
    lone = tmp_path / "lone.pt"
    shutil.copy(a, lone)
    with pytest.raises(CheckpointError, match=r"no resolved_config\.yaml"):
        soup.make_soup([a, lone], tmp_path / "soup")
    assert not (tmp_path / "soup" / "checkpoints" / "final.pt").exists()
