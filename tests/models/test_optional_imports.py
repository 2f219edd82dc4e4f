"""Without torch (or stable-baselines3) installed, importing the models and trainers fails with
a `MissingExtraError` that says what to install, not a bare ModuleNotFoundError."""

from __future__ import annotations

import subprocess
import sys

import pytest

SCRIPT = """
import sys
sys.modules[{blocked!r}] = None  # what an environment without the package looks like to import
from selfplaydrive.errors import MissingExtraError
try:
    import {module}
except MissingExtraError as exc:
    print("MissingExtraError:", exc)
"""


@pytest.mark.parametrize(
    ("blocked", "module", "hint"),
    [
        ("torch", "selfplaydrive.models", "pip install torch"),
        ("torch", "selfplaydrive.trainers", "pip install torch"),
        ("stable_baselines3", "selfplaydrive.trainers.sb3", "selfplaydrive[sb3]"),
    ],
)
def test_missing_extra_names_what_to_install(blocked, module, hint):
    out = subprocess.run(
        [sys.executable, "-c", SCRIPT.format(blocked=blocked, module=module)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("MissingExtraError:") and hint in out.stdout, out.stdout
