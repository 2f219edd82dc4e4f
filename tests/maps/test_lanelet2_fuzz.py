"""Fuzz the Lanelet2 loader: mutated cuts of real maps either load or raise MapError.

Cuts of Town02 (lat/lon, traffic lights without lanelet references), Tartu (local_x/local_y,
crosswalks, line types) and the Lanelet2 example (bidirectional lanelets, right_of_way) are
written to tmp_path, then mutated with a seeded generator: deleted and duplicated lines,
corrupted numbers, truncation, swapped ids. Every mutant must either load and compile or raise
`MapError` naming the file; any other exception, or a run longer than a few seconds (SIGALRM),
fails the test.
"""

from __future__ import annotations

import re
import signal
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from sharedmaps import shared_map

from selfplaydrive.errors import MapError
from selfplaydrive.maps import compile_map
from selfplaydrive.maps.lanelet2 import read_lanelet2

NUM_MUTANTS = 40  # per source map, 120 in all
PER_FILE_LIMIT_S = 5
_NUMBER = re.compile(r'(?<=")-?\d+(?:\.\d+)?(?:[eE]-?\d+)?(?=")')
_ID = re.compile(r'(?:id|ref)="(-?\d+)"')
_BAD_NUMBERS = ["nan", "inf", "-inf", "abc", "", "1e400", "0", "-1", "1e20", "99999999999999999999999"]


def _cut(src: Path, dst: Path, max_lanelets: int) -> None:
    """Write the `max_lanelets` lanelets nearest the map's first traffic light, the regulatory
    elements around them and the ways and nodes all these use, as an indented OSM file."""
    root = ET.parse(src).getroot()
    nodes = {e.get("id"): e for e in root if e.tag == "node"}
    ways = {e.get("id"): e for e in root if e.tag == "way"}
    rels = {e.get("id"): e for e in root if e.tag == "relation"}

    def kind(r):
        return {t.get("k"): (t.get("v") or "").strip() for t in r.findall("tag")}.get("type")

    def pos(way_id):
        n = nodes[ways[way_id].find("nd").get("ref")]
        return np.array([float(n.get("lat")), float(n.get("lon"))])

    lanelets = [r for r in rels.values() if kind(r) == "lanelet"]
    regs = [r for r in rels.values() if kind(r) == "regulatory_element"]
    lines = [m.get("ref") for r in regs for m in r.findall("member[@role='ref_line']")]
    centre = pos(lines[0] if lines else lanelets[0].find("member[@role='left']").get("ref"))

    def dist(way_id):
        return float(np.hypot(*(pos(way_id) - centre)))

    near = sorted(lanelets, key=lambda r: dist(r.find("member[@role='left']").get("ref")))[:max_lanelets]
    radius = max(dist(r.find("member[@role='left']").get("ref")) for r in near)
    keep_ids = {r.get("id") for r in near}
    kept_regs = [
        r for r in regs if all(dist(m.get("ref")) <= radius for m in r.findall("member[@type='way']"))
    ]
    for reg in kept_regs:
        for m in list(reg.findall("member[@type='relation']")):
            if m.get("ref") not in keep_ids:
                reg.remove(m)
    keep_ids |= {r.get("id") for r in kept_regs}
    for r in near:
        for m in list(r.findall("member[@type='relation']")):
            if m.get("ref") not in keep_ids:
                r.remove(m)
    keep_rels = near + kept_regs
    way_ids = {m.get("ref") for r in keep_rels for m in r.findall("member[@type='way']")}
    node_ids = {nd.get("ref") for w in way_ids for nd in ways[w].findall("nd")}
    out = ET.Element("osm", version="0.6")
    out.extend(nodes[n] for n in sorted(node_ids, key=int))
    out.extend(ways[w] for w in sorted(way_ids, key=int))
    out.extend(keep_rels)
    ET.indent(out)
    dst.write_bytes(ET.tostring(out, encoding="utf-8", xml_declaration=True))


def _mutate(text: str, rng: np.random.Generator) -> str:
    kind = int(rng.integers(5))
    lines = text.split("\n")
    if kind == 0:  # delete 1-5 random lines
        for _ in range(int(rng.integers(1, 6))):
            del lines[int(rng.integers(len(lines)))]
        return "\n".join(lines)
    if kind == 1:  # duplicate a line
        k = int(rng.integers(len(lines)))
        return "\n".join(lines[: k + 1] + lines[k:])
    if kind == 2:  # corrupt 1-3 numbers
        for _ in range(int(rng.integers(1, 4))):
            spans = [m.span() for m in _NUMBER.finditer(text)]
            a, b = spans[int(rng.integers(len(spans)))]
            text = text[:a] + _BAD_NUMBERS[int(rng.integers(len(_BAD_NUMBERS)))] + text[b:]
        return text
    if kind == 3:  # truncate
        return text[: int(rng.integers(len(text)))]
    ids = [m.span(1) for m in _ID.finditer(text)]  # swap two ids / references
    (a0, a1), (b0, b1) = sorted(ids[int(k)] for k in rng.choice(len(ids), size=2, replace=False))
    return text[:a0] + text[b0:b1] + text[a1:b0] + text[a0:a1] + text[b1:]


class _TimeoutError(Exception):
    pass


def _alarm(signum, frame):
    raise _TimeoutError


@pytest.mark.parametrize(
    ("rel", "max_lanelets", "seed"),
    [
        ("carla_lanelet2/Town02.osm", 6, 0),
        ("tartu_lanelet2/tartu_demo_l.osm", 25, 1),
        ("lanelet2_example/mapping_example.osm", 30, 2),
    ],
)
def test_mutants_load_or_raise_map_error(tmp_path, rel, max_lanelets, seed):
    base = tmp_path / "cut.osm"
    _cut(shared_map(rel), base, max_lanelets)
    compile_map(read_lanelet2(base))  # the unmutated cut is a valid map
    text = base.read_text()
    rng = np.random.default_rng(seed)
    outcomes = {"loaded": 0, "MapError": 0}
    old = signal.signal(signal.SIGALRM, _alarm)
    start = time.perf_counter()
    try:
        for k in range(NUM_MUTANTS):
            path = tmp_path / f"mutant_{k:03d}.osm"
            path.write_text(_mutate(text, rng))
            signal.alarm(PER_FILE_LIMIT_S)
            try:
                compile_map(read_lanelet2(path))
                outcomes["loaded"] += 1
            except MapError as err:
                assert str(path) in str(err), f"{path.name}: MapError does not name the file: {err}"
                outcomes["MapError"] += 1
            except _TimeoutError:
                pytest.fail(f"{path.name}: no result within {PER_FILE_LIMIT_S} s")
            finally:
                signal.alarm(0)
    finally:
        signal.signal(signal.SIGALRM, old)
    # both outcomes occur: the mutations are neither all harmless nor all fatal
    assert outcomes["loaded"] > 0 and outcomes["MapError"] > 0, outcomes
    assert time.perf_counter() - start < 20.0
