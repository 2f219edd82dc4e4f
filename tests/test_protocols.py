"""The component Protocols (physics/base.py, obs/base.py, rewards/base.py, scenario/base.py):
the shipped components satisfy them, statically (mypy) and at run time."""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

from selfplaydrive.physics import BicycleModel, FrictionBicycleModel, PymunkModel
from selfplaydrive.physics.base import ExternalPhysicsModel, PhysicsModel
from selfplaydrive.rewards import KernelTerm, LinearReward, RewardHook, RewardModule, get_term
from selfplaydrive.scenario import PaperSpawner, Spawner

ROOT = Path(__file__).resolve().parents[1]
CACHE = str(Path(tempfile.gettempdir()) / "selfplaydrive-mypy-cache")

# assignments mypy checks structurally: an error here means a component left its Protocol
STATIC = """
from selfplaydrive.eval.logged.run import LogSpawner
from selfplaydrive.eval.suites.base import FixedScenarioSpawner
from selfplaydrive.physics import BicycleModel, FrictionBicycleModel, PymunkModel
from selfplaydrive.physics.base import ExternalPhysicsModel, PhysicsModel
from selfplaydrive.render.record import ScenarioLog
from selfplaydrive.rewards import LinearReward, RewardModule
from selfplaydrive.scenario import PaperSpawner, Spawner

physics: list[PhysicsModel] = [BicycleModel(), FrictionBicycleModel(), PymunkModel()]
external: ExternalPhysicsModel = PymunkModel()
reward: RewardModule = LinearReward()
spawners: list[type[Spawner]] = [PaperSpawner, FixedScenarioSpawner, LogSpawner, ScenarioLog]
"""


class Speed:
    name = "speed"

    def __call__(self, state: object) -> np.ndarray:
        return np.zeros(1, np.float32)


def test_shipped_components_satisfy_the_protocols_statically(tmp_path):
    pytest.importorskip("mypy")
    src = tmp_path / "conformance.py"
    src.write_text(STATIC)
    r = subprocess.run(
        [sys.executable, "-m", "mypy", "--cache-dir", CACHE, "--config-file", "pyproject.toml", str(src)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert r.returncode == 0, r.stdout + r.stderr


def test_runtime_checks():
    for model in (BicycleModel(), FrictionBicycleModel()):
        assert isinstance(model, PhysicsModel) and not isinstance(model, ExternalPhysicsModel)
    pytest.importorskip("pymunk")
    assert isinstance(PymunkModel(), ExternalPhysicsModel)
    assert isinstance(LinearReward(), RewardModule)
    assert isinstance(PaperSpawner(), Spawner) and not isinstance(object(), Spawner)
    assert isinstance(Speed(), RewardHook)
    assert isinstance(get_term("collision"), KernelTerm) and not isinstance(get_term("collision"), RewardHook)
