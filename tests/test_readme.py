"""The README's two commands and CI agree: `.ci/run` runs the README's test command, in a fresh
virtual environment, so a missing install step fails CI rather than a new user's install."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _bash_blocks(text: str) -> list[str]:
    return [b.strip() for b in re.findall(r"```bash\n(.*?)```", text, flags=re.S)]


def test_readme_opens_with_the_main_job_and_the_test_command() -> None:
    blocks = _bash_blocks((ROOT / "README.md").read_text())
    main_job, tests = blocks[0], blocks[1]
    assert main_job.endswith("selfplaydrive train")
    assert tests.endswith("python -m pytest")
    for command in (main_job, tests):
        assert "torch==2.13.0" in command  # the CPU wheel; a bare `torch` pulls CUDA packages
        assert "--no-build-isolation -e" in command


def test_ci_runs_the_readme_test_command_in_a_fresh_venv() -> None:
    readme_tests = _bash_blocks((ROOT / "README.md").read_text())[1]
    ci = (ROOT / ".ci" / "run").read_text()
    lines = [line.strip() for line in ci.splitlines()]
    assert readme_tests in lines, ".ci/run no longer runs the README's test command verbatim"
    venv = next(i for i, line in enumerate(lines) if line.startswith('python -m venv "$WORK/venv"'))
    activate = next(i for i, line in enumerate(lines) if line.startswith('source "$WORK/venv/bin/activate"'))
    assert venv < activate < lines.index(readme_tests)
    assert "--system-site-packages" not in ci
    # the install without extras and its first commands
    assert re.search(r'bare/bin/python" -m pip install --no-build-isolation "\$REPO"\n', ci)
    for command in ("map info default", "eval --help"):
        assert command in ci
