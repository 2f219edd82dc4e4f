"""`selfplaydrive train|render|bench --help` name the command (not Hydra's 'hydra_app') and list
the configuration groups the command reads, each with the options that exist in conf/."""

from __future__ import annotations

import re

import pytest

from selfplaydrive.builder import valid_options
from selfplaydrive.cli import main

ENV_GROUPS = {"map", "spawner", "physics", "reward", "obs", "env"}


@pytest.mark.parametrize(
    "command,groups",
    [
        ("train", ENV_GROUPS | {"model", "trainer", "logger", "experiment"}),
        ("render", ENV_GROUPS),
        ("bench", ENV_GROUPS),
    ],
)
def test_help_names_the_command_and_its_groups(command, groups, capsys):
    with pytest.raises(SystemExit) as info:
        main([command, "--help"])
    assert info.value.code == 0
    text = capsys.readouterr().out
    assert text.startswith(f"selfplaydrive {command}:")
    assert "hydra_app" not in text
    section = text.split("== Configuration groups")[1].split("== Config ==")[0]
    listed = dict(re.findall(r"^(\w+): ([\w, ]+?)(?:\s{2,}|\n)", section, flags=re.MULTILINE))
    assert set(listed) == groups
    for group, options in listed.items():
        assert options.strip().split(", ") == valid_options(group), f"help lists stale options of {group}"
