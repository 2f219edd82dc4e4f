"""Spawn sanity (paper section 5.2: 20 % of the Waymax failures were vehicles spawned in front
of or inside the ego): the classifier on hand-placed bodies, and the paper's spawner on the
bundled town and on Tartu."""

from __future__ import annotations

import copy

import numpy as np
import pytest
from sharedmaps import shared_map

from selfplaydrive.eval.suites import SpawnSanitySuite, classify_spawn
from selfplaydrive.eval.suites.base import SuiteScenario
from selfplaydrive.maps.loader import load_map


@pytest.fixture(scope="module")
def town():
    return load_map("default")


@pytest.fixture(scope="module")
def scene(town):
    """One spawned scenario of the bundled town, found clear, to edit by hand."""
    suite = SpawnSanitySuite()
    item = suite.generate(town, np.random.default_rng(0), 1)[0]
    assert classify_spawn(item)["outcome"] == "clear"
    return item


def _edit(item: SuiteScenario) -> SuiteScenario:
    return SuiteScenario(item.suite, copy.deepcopy(item.scenario), {}, dict(item.info))


def _ahead(sc, slot: int, metres: float) -> np.ndarray:
    h = float(sc.agent_heading[slot])
    return sc.agent_xy[slot] + metres * np.array([np.cos(h), np.sin(h)], np.float32)


def test_agent_inside_another_is_an_overlap(scene):
    item = _edit(scene)
    sc = item.scenario
    sc.agent_xy[1] = _ahead(sc, 0, 1.0)
    sc.agent_heading[1] = sc.agent_heading[0]
    res = classify_spawn(item)
    assert res["outcome"] == "overlap" and {0, 1} <= set(res["overlap"])
    assert {h["body"] for h in res["hits"] if h["slot"] == 0} == {"agent"}


@pytest.mark.parametrize("body", ["static", "pedestrian"])
def test_body_within_one_second_ahead_is_close(scene, body):
    """A body 2 m beyond the front bumper: close ahead at 5 m/s, clear when standing, clear
    behind the reach at 1 m/s."""
    item = _edit(scene)
    sc = item.scenario
    gap = float(sc.agent_length[0]) / 2 + 2.0 + 0.5  # the body's near side 2 m past the bumper
    if body == "static":
        sc.static_valid[0] = True
        sc.static_xy[0] = _ahead(sc, 0, gap + 2.0)
        sc.static_heading[0] = sc.agent_heading[0]
        sc.static_length[0], sc.static_width[0] = 4.0, 1.8
    else:
        sc.ped_valid[0] = True
        sc.ped_path[0, :] = _ahead(sc, 0, gap)
        sc.ped_path[0, 1:] += np.float32(5.0)
        sc.ped_size[0] = (1.0, 1.0)
    for speed, want in ((5.0, "close_ahead"), (0.0, "clear"), (1.0, "clear")):
        sc.agent_speed[0] = speed
        res = classify_spawn(item)
        flagged = [h for h in res["hits"] if h["slot"] == 0]
        assert (flagged[0]["what"] if flagged else "clear") == want, speed
        if flagged:
            assert flagged[0]["body"] == body


def test_paper_spawner_on_bundled_town(town):
    suite = SpawnSanitySuite()
    with pytest.warns(UserWarning):  # the spawner's own shortfall notice; not this check's concern
        items = suite.generate(town, np.random.default_rng(1), 40)
    summary = suite.summarise([suite.classify(i) for i in items])
    assert summary["n"] == 40 and summary["agents"] > 40 * 20
    assert summary["overlap"]["numerator"] == 0 and summary["close_ahead"]["numerator"] == 0


def test_paper_spawner_on_tartu():
    """No overlaps; a pedestrian within 1 s of an agent happens (docs/suites.md: 1 agent in
    9461, seed 0), so only its rarity is asserted."""
    tartu = load_map(str(shared_map("tartu_lanelet2/tartu_demo_l.osm")))
    suite = SpawnSanitySuite()
    items = suite.generate(tartu, np.random.default_rng(1), 40)
    summary = suite.summarise([suite.classify(i) for i in items])
    assert summary["overlap"]["numerator"] == 0
    assert summary["agents_flagged"]["value"] < 0.01
    assert summary["agents_by_body"]["agent"] == 0 and summary["agents_by_body"]["static"] == 0
