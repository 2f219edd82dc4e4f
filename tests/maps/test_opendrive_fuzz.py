"""Fuzz the OpenDRIVE loader: seeded mutations of a small real map either load or raise MapError.

The base map is one signalised junction (id 725) of CARLA Town07 (2020 export, with traffic lights,
controllers and crosswalks) and the roads attached to it, cut out at test time.
"""

from __future__ import annotations

import re
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from sharedmaps import shared_map

from selfplaydrive.errors import MapError
from selfplaydrive.maps.compile import compile_map
from selfplaydrive.maps.opendrive import read_opendrive

NUM_MUTATIONS = 120
_NUMBER = re.compile(r'"(-?[0-9][0-9.eE+-]*)"')
_ID = re.compile(r'(id|elementId|incomingRoad|connectingRoad|signalId)="([^"]*)"')


def _cut_junction(src: Path, junction: str) -> str:
    """Text of an .xodr holding one junction, its connecting roads and the roads around it."""
    root = ET.parse(src).getroot()
    roads = {r.get("id"): r for r in root.findall("road")}
    inner = {rid for rid, r in roads.items() if r.get("junction") == junction}
    keep = set(inner)
    for rid in inner:
        for link in roads[rid].find("link") or []:
            if link.get("elementType") == "road":
                keep.add(link.get("elementId"))
    for child in list(root):
        drop_road = child.tag == "road" and child.get("id") not in keep
        drop_junction = child.tag == "junction" and child.get("id") != junction
        if drop_road or drop_junction:
            root.remove(child)
    return ET.tostring(root, encoding="unicode")


@pytest.fixture(scope="module")
def base_text() -> str:
    return _cut_junction(shared_map("carla_opendrive_2020/Town07.xodr"), "725")


def _mutate(text: str, rng: np.random.Generator) -> str:
    kind = rng.integers(6)
    lines = text.splitlines(keepends=True)
    if kind == 0:  # truncate
        return text[: int(rng.integers(0, len(text)))]
    if kind == 1:  # delete a few lines
        for _ in range(int(rng.integers(1, 6))):
            del lines[int(rng.integers(len(lines)))]
        return "".join(lines)
    if kind in (2, 3):  # corrupt numbers
        matches = list(_NUMBER.finditer(text))
        for _ in range(int(rng.integers(1, 4))):
            m = matches[int(rng.integers(len(matches)))]
            new = rng.choice(
                ["nan", "inf", "-inf", "", "abc", "1e300", "-1e300", "1e5", "0", "-5", "0.0001", "7"]
            )
            text = text[: m.start(1)] + str(new) + text[m.end(1) :]
            matches = list(_NUMBER.finditer(text))
        return text
    if kind == 4:  # change ids
        matches = list(_ID.finditer(text))
        for _ in range(int(rng.integers(1, 4))):
            m = matches[int(rng.integers(len(matches)))]
            new = rng.choice(["0", "1", "-1", "999", "x", "", "68", "-2"])
            text = text[: m.start(2)] + str(new) + text[m.end(2) :]
            matches = list(_ID.finditer(text))
        return text
    # rename or swap tags
    tags = ["line", "arc", "spiral", "bezier", "lane", "road", "laneSection", "signal", "width", "geometry"]
    old, new = rng.choice(tags, size=2, replace=False)
    return text.replace(f"<{old}", f"<{new}", int(rng.integers(1, 3)))


def test_base_map_loads(base_text: str, tmp_path: Path) -> None:
    path = tmp_path / "junction725.xodr"
    path.write_text(base_text)
    elements = read_opendrive(path)
    road_map = compile_map(elements)
    assert len(elements.lanes) > 20
    assert elements.traffic_lights and elements.crosswalks
    assert road_map.lanes.succ_index.size > 0


def test_mutations_load_or_raise_map_error(base_text: str, tmp_path: Path) -> None:
    rng = np.random.default_rng(1234)
    outcomes = {"loaded": 0, "map_error": 0}
    start = time.perf_counter()
    for i in range(NUM_MUTATIONS):
        path = tmp_path / f"mutant_{i:03d}.xodr"
        path.write_text(_mutate(base_text, rng))
        try:
            compile_map(read_opendrive(path))
            outcomes["loaded"] += 1
        except MapError as e:
            assert str(path) in str(e), f"mutation {i}: error does not name the file: {e}"
            outcomes["map_error"] += 1
        except Exception as e:
            pytest.fail(f"mutation {i} ({path}) raised {type(e).__name__}: {e}")
    elapsed = time.perf_counter() - start
    assert outcomes["loaded"] > 0 and outcomes["map_error"] > 0, outcomes
    assert elapsed < 20.0, f"{NUM_MUTATIONS} mutations took {elapsed:.1f} s"
