"""Paths to ../shared/maps for tests; a test that needs a missing file skips with a reason.

A module of its own (not conftest.py) so test files can import it without clashing with the
other conftest.py files of sub-folders.
"""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_MAPS = REPO.parent / "shared" / "maps"


def shared_map(rel: str) -> Path:
    """Path of a file under ../shared/maps, or skip the test with a reason."""
    path = SHARED_MAPS / rel
    if not path.exists():
        pytest.skip(f"{path} not present: ../shared/maps is only available in the project's CI")
    return path
