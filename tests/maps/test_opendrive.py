"""OpenDRIVE loader: lanes, directions, graph, neighbours, signals, crosswalks, errors, real maps."""
# ruff: noqa: E501  (inline XML fixtures read better unwrapped)

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from sharedmaps import shared_map

from selfplaydrive.errors import ConfigError, MapError
from selfplaydrive.maps.compile import compile_map
from selfplaydrive.maps.elements import LaneKind, MapElements, StopKind
from selfplaydrive.maps.opendrive import OpenDriveLoader, parse_opendrive, read_opendrive
from selfplaydrive.maps.routing import largest_scc_share

W = 'sOffset="0" a="{a}" b="{b}" c="0" d="0"'


def _lane(
    lid: int,
    typ: str = "driving",
    width: float = 3.5,
    mark: str | None = None,
    link: str = "",
    extra: str = "",
) -> str:
    mark_xml = f'<roadMark sOffset="0" type="{mark}"/>' if mark else ""
    return f'<lane id="{lid}" type="{typ}">{link}<width {W.format(a=width, b=0)}/>{mark_xml}{extra}</lane>'


def _road(rid: str, x: float, y: float, hdg: float, length: float, left: str, right: str, junction: str = "-1",
          link: str = "", extra: str = "", rule: str = "", sections: str | None = None) -> str:  # fmt: skip
    rule_attr = f' rule="{rule}"' if rule else ""
    secs = sections or (
        f'<laneSection s="0"><left>{left}</left><center><lane id="0" type="none"/></center>'
        f"<right>{right}</right></laneSection>"
    )
    return (
        f'<road id="{rid}" length="{length}" junction="{junction}"{rule_attr}><link>{link}</link>'
        f'<planView><geometry s="0" x="{x}" y="{y}" hdg="{hdg}" length="{length}"><line/></geometry></planView>'
        f'<lanes><laneOffset s="0" a="0" b="0" c="0" d="0"/>{secs}</lanes>{extra}</road>'
    )


def _write(tmp_path: Path, body: str, name: str = "map.xodr") -> Path:
    path = tmp_path / name
    path.write_text(f'<?xml version="1.0"?><OpenDRIVE><header revMajor="1" revMinor="6"/>{body}</OpenDRIVE>')
    return path


def _by_id(elements: MapElements) -> dict[str, int]:
    return {lane.source_id: i for i, lane in enumerate(elements.lanes)}


def _straight(tmp_path: Path, mark: str | None = "broken", rule: str = "") -> MapElements:
    left = _lane(2, "sidewalk", 2.0) + _lane(1, mark="solid")
    right = (
        _lane(-1, mark=mark)
        + f'<lane id="-2" type="driving"><width {W.format(a=3.0, b=0.01)}/></lane>'
        + _lane(-3, "shoulder", 1.0)
    )
    speed = '<type s="0" type="town"><speed max="30" unit="mph"/></type>'
    return read_opendrive(_write(tmp_path, _road("1", 0, 0, 0, 100, left, right, extra=speed, rule=rule)))


def test_lane_centerlines_directions_and_widths(tmp_path: Path) -> None:
    e = _straight(tmp_path)
    ids = _by_id(e)
    assert set(ids) == {"road 1/section 0/lane 1", "road 1/section 0/lane -1", "road 1/section 0/lane -2"}
    r1, r2, l1 = (e.lanes[ids[f"road 1/section 0/lane {k}"]] for k in (-1, -2, 1))
    # right lanes follow the reference line (+x), left lanes run against it
    np.testing.assert_allclose(r1.centerline[[0, -1]], [[0, -1.75], [100, -1.75]], atol=1e-9)
    np.testing.assert_allclose(l1.centerline[[0, -1]], [[100, 1.75], [0, 1.75]], atol=1e-9)
    # lane -2: width 3 + 0.01 ds, centre at -3.5 - w / 2
    np.testing.assert_allclose(r2.centerline[[0, -1]], [[0, -5.0], [100, -5.5]], atol=1e-9)
    assert r2.width == pytest.approx(3.5, abs=0.01)
    assert r1.speed_limit == pytest.approx(30 * 0.44704)
    assert all(lane.kind == LaneKind.VEHICLE and not lane.in_junction for lane in e.lanes)
    assert len(r1.centerline) == 101  # sample_step 1 m


def test_left_hand_traffic_reverses_directions(tmp_path: Path) -> None:
    e = _straight(tmp_path, rule="LHT")
    ids = _by_id(e)
    assert e.lanes[ids["road 1/section 0/lane -1"]].centerline[0, 0] == pytest.approx(100)
    assert e.lanes[ids["road 1/section 0/lane 1"]].centerline[0, 0] == pytest.approx(0)


@pytest.mark.parametrize(
    ("mark", "legal"), [("broken", True), ("solid", False), (None, True), ("solid solid", False)]
)
def test_neighbours_and_lane_change_legality(tmp_path: Path, mark: str | None, legal: bool) -> None:
    e = _straight(tmp_path, mark=mark)
    ids = _by_id(e)
    r1, r2, l1 = (ids[f"road 1/section 0/lane {k}"] for k in (-1, -2, 1))
    # travelling +x: lane -1 is left of lane -2; the oncoming lane 1 is nobody's neighbour
    assert (e.lanes[r2].left, e.lanes[r2].left_change_legal) == (r1, legal)
    assert (e.lanes[r1].right, e.lanes[r1].right_change_legal) == (r2, legal)
    assert e.lanes[r1].left == -1 and e.lanes[l1].left == -1 and e.lanes[l1].right == -1


def test_road_edges_are_outer_borders_of_drivable_lanes(tmp_path: Path) -> None:
    e = _straight(tmp_path)
    ys = sorted((float(edge.points[0, 1]), float(edge.points[-1, 1])) for edge in e.road_edges)
    # right: outer border of lane -2 (-3.5 - width); left: outer border of lane 1 (sidewalk ignored)
    assert ys == [(-6.5, -7.5), (3.5, 3.5)]


def _network(tmp_path: Path) -> MapElements:
    lk = '<link><predecessor id="{p}"/><successor id="{s}"/></link>'
    sec = (
        '<laneSection s="{s}"><left>'
        + _lane(1, link=lk.format(p=1, s=1))
        + '</left><center><lane id="0"/></center>'
        "<right>" + _lane(-1, link=lk.format(p=-1, s=-1)) + "</right></laneSection>"
    )
    controller = '<controller id="c1"><control signalId="100"/><control signalId="101"/></controller>'
    signals1 = (
        '<signals><signal id="100" s="48" t="-5" orientation="+" dynamic="yes" type="1000001">'
        '<validity fromLane="0" toLane="0"/></signal></signals>'
    )
    ref2 = '<signals><signalReference id="100" s="0" t="0" orientation="+"><validity fromLane="-1" toLane="-1"/></signalReference></signals>'
    ref4 = '<signals><signalReference id="101" s="0" t="0" orientation="+"><validity fromLane="-1" toLane="-1"/></signalReference></signals>'
    signals3 = (
        '<signals><signal id="101" s="2" t="5" dynamic="yes" type="1000001" orientation="-"/>'
        '<signal id="200" s="40" t="-5" orientation="+" dynamic="no" type="206"/>'
        '<signal id="201" s="10" t="5" orientation="-" dynamic="no" type="205"><validity fromLane="1" toLane="1"/></signal>'
        '<signal id="202" s="10" t="5" orientation="-" dynamic="no" type="274"/></signals>'
    )
    objects3 = (
        '<objects><object id="cw1" type="crosswalk" s="25" t="0" hdg="0"><outline>'
        '<cornerLocal u="1" v="-3.5"/><cornerLocal u="1" v="3.5"/><cornerLocal u="-1" v="3.5"/><cornerLocal u="-1" v="-3.5"/>'
        '</outline></object><object id="cw2" type="crosswalk" s="45" t="0" hdg="0" length="2" width="7"/>'
        '<object id="pole" type="pole" s="45" t="6" length="0.2" width="0.2"/></objects>'
    )
    road1 = _road("1", 0, 0, 0, 50, "", "", link='<successor elementType="junction" elementId="10"/>',
                  sections=sec.format(s=0) + sec.format(s=30), extra=signals1)  # fmt: skip
    road2 = _road("2", 50, 0, 0, 20, "", _lane(-1, link=lk.format(p=-1, s=-1)), junction="10", extra=ref2,
                  link='<predecessor elementType="road" elementId="1" contactPoint="end"/>'
                  '<successor elementType="road" elementId="3" contactPoint="start"/>')  # fmt: skip
    road3 = _road("3", 70, 0, 0, 50, _lane(1), _lane(-1), link='<predecessor elementType="junction" elementId="10"/>',
                  extra=signals3 + objects3)  # fmt: skip
    road4 = _road("4", 70, 0, math.pi, 20, "", _lane(-1, link=lk.format(p=1, s=1)), junction="10", extra=ref4,
                  link='<predecessor elementType="road" elementId="3" contactPoint="start"/>'
                  '<successor elementType="road" elementId="1" contactPoint="end"/>')  # fmt: skip
    junction = (
        '<junction id="10"><connection id="0" incomingRoad="1" connectingRoad="2" contactPoint="start">'
        '<laneLink from="-1" to="-1"/></connection><connection id="1" incomingRoad="3" connectingRoad="4" '
        'contactPoint="start"><laneLink from="1" to="-1"/></connection></junction>'
    )
    return read_opendrive(_write(tmp_path, road1 + road2 + road3 + road4 + junction + controller))


def test_lane_graph_across_sections_roads_and_junctions(tmp_path: Path) -> None:
    e = _network(tmp_path)
    i = _by_id(e)
    a0, a1 = i["road 1/section 0/lane -1"], i["road 1/section 1/lane -1"]
    b0, b1 = i["road 1/section 0/lane 1"], i["road 1/section 1/lane 1"]
    j2, j4 = i["road 2/section 0/lane -1"], i["road 4/section 0/lane -1"]
    c_out, c_in = i["road 3/section 0/lane -1"], i["road 3/section 0/lane 1"]
    assert e.lanes[a0].successors == [a1]
    assert e.lanes[a1].successors == [j2]
    assert e.lanes[j2].successors == [c_out]
    assert e.lanes[c_out].successors == []
    assert e.lanes[c_in].successors == [j4]
    assert e.lanes[j4].successors == [b1]
    assert e.lanes[b1].successors == [b0]
    assert [lane.in_junction for lane in (e.lanes[j2], e.lanes[j4], e.lanes[a1])] == [True, True, False]
    # the connector in road 4 runs from x = 70 back to x = 50 at y = +1.75
    np.testing.assert_allclose(e.lanes[j4].centerline[[0, -1]], [[70, 1.75], [50, 1.75]], atol=1e-9)


def test_signals_stop_lines_and_groups(tmp_path: Path) -> None:
    e = _network(tmp_path)
    i = _by_id(e)
    lights = sorted(e.traffic_lights, key=lambda t: t.source_id)
    assert len(lights) == 2
    # light 100 is referenced on connector 2, so its line crosses the end of its approach lane
    np.testing.assert_allclose(sorted(lights[0].points[:, 1]), [-3.5, 0.0], atol=1e-9)
    np.testing.assert_allclose(lights[0].points[:, 0], [50, 50], atol=1e-9)
    assert lights[0].lanes == [i["road 1/section 1/lane -1"]]
    # light 101 (reference on connector 4): approach lane 1 of road 3 ends at x = 70
    np.testing.assert_allclose(lights[1].points[:, 0], [70, 70], atol=1e-9)
    assert lights[1].lanes == [i["road 3/section 0/lane 1"]]
    assert lights[0].signal_group == lights[1].signal_group  # same <controller>
    stops = {s.source_id.split(" (")[0]: s for s in e.stop_lines}
    assert set(stops) == {"signal 200", "signal 201"}  # the 274 speed sign is not a stop line
    stop, yld = stops["signal 200"], stops["signal 201"]
    assert stop.kind == StopKind.STOP and yld.kind == StopKind.YIELD
    # stop sign at s = 40, orientation "+": lanes travelling +s (lane -1)
    np.testing.assert_allclose(stop.points, [[110, 0], [110, -3.5]], atol=1e-9)
    assert stop.lanes == [i["road 3/section 0/lane -1"]]
    # yield sign with validity 1..1 at s = 10
    np.testing.assert_allclose(yld.points, [[80, 3.5], [80, 0]], atol=1e-9)
    assert yld.lanes == [i["road 3/section 0/lane 1"]]


def test_crosswalk_polygons(tmp_path: Path) -> None:
    e = _network(tmp_path)
    assert [c.source_id for c in e.crosswalks] == ["road 3/object cw1", "road 3/object cw2"]
    for c in e.crosswalks:
        lo, hi = c.polygon.min(axis=0), c.polygon.max(axis=0)
        cx = 95 if c.source_id.endswith("cw1") else 115
        np.testing.assert_allclose([lo, hi], [[cx - 1, -3.5], [cx + 1, 3.5]], atol=1e-9)


@pytest.mark.parametrize(
    "kwargs", [{"sample_step": 0}, {"default_speed_limit": -1}, {"max_segment_length": float("nan")}]
)
def test_loader_rejects_bad_arguments(kwargs: dict) -> None:
    with pytest.raises(ConfigError, match=next(iter(kwargs))):
        OpenDriveLoader("unused.xodr", **kwargs)


def test_loader_on_real_map() -> None:
    road_map = OpenDriveLoader(str(shared_map("carla_opendrive_2020/Town02.xodr"))).load()
    assert len(road_map.light_group) == 24 and largest_scc_share(road_map) > 0.99


def test_loader_compiles_and_default_speed(tmp_path: Path) -> None:
    path = _write(tmp_path, _road("7", 0, 0, 0, 30, _lane(1), _lane(-1)))
    road_map = OpenDriveLoader(
        str(path), sample_step=2.0, default_speed_limit=10.0, max_segment_length=5.0
    ).load()
    assert len(road_map.lanes) == 2
    np.testing.assert_allclose(road_map.lanes.speed_limit, 10.0)
    assert road_map.segments.length.max() <= 5.0 + 1e-4


def _error(path: Path) -> str:
    with pytest.raises(MapError) as info:
        read_opendrive(path)
    msg = str(info.value)
    assert str(path) in msg
    return msg


def test_errors_name_file_and_element(tmp_path: Path) -> None:
    good = _road("5", 0, 0, 0, 30, _lane(1), _lane(-1))
    truncated = _write(tmp_path, good, "t.xodr")
    truncated.write_text(truncated.read_text()[:-120])
    assert "not well-formed" in _error(truncated)
    no_length = _write(tmp_path, good.replace(' length="30" junction', " junction"), "l.xodr")
    assert "road 5" in _error(no_length) and "'length'" in _error(no_length)
    nan = _write(tmp_path, good.replace('x="0"', 'x="nan"'), "n.xodr")
    assert "road 5" in _error(nan) and "finite" in _error(nan)
    bezier = _write(tmp_path, good.replace("<line/>", '<bezier a="1"/>'), "b.xodr")
    msg = _error(bezier)
    assert "road 5" in msg and "bezier" in msg
    assert "no <road>" in _error(_write(tmp_path, "", "e.xodr"))
    no_drivable = _write(
        tmp_path, _road("6", 0, 0, 0, 30, _lane(1, "sidewalk"), _lane(-1, "shoulder")), "d.xodr"
    )
    assert "no drivable lanes" in _error(no_drivable)
    bad_lane = _write(tmp_path, good.replace('<lane id="-1"', '<lane id="-x"'), "i.xodr")
    assert "road 5/laneSection 0" in _error(bad_lane)
    bad_width = _write(tmp_path, good.replace('a="3.5"', 'a="1e200"', 1), "w.xodr")
    assert "lane" in _error(bad_width)
    assert "cannot read" in _error(tmp_path / "missing.xodr")


# (folder/file, driving-lane km from ../shared/maps/README.md)
REAL_MAPS = [
    ("carla_opendrive/Town01.xodr", 6.4),
    ("carla_opendrive/Town02.xodr", 2.9),
    ("carla_opendrive/Town03.xodr", 13.2),
    ("carla_opendrive/Town04.xodr", 33.1),
    ("carla_opendrive/Town06.xodr", 25.3),
    ("carla_opendrive/Town07.xodr", 7.1),
    ("carla_opendrive_2020/Town01.xodr", 6.4),
    ("carla_opendrive_2020/Town02.xodr", 2.9),
    ("carla_opendrive_2020/Town07.xodr", 7.1),
]


def driving_km(path: Path, elements: MapElements) -> float:
    """Centerline km of lanes of OpenDRIVE type "driving", junction connectors included."""
    odr = parse_opendrive(path)
    total = 0.0
    for lane in elements.lanes:
        road, sec, lid = (part.split()[1] for part in lane.source_id.split("/")[:3])
        if odr.roads[road].sections[int(sec)].lanes[int(lid)].type == "driving":
            total += float(np.sum(np.hypot(*np.diff(lane.centerline, axis=0).T)))
    return total / 1000.0


@pytest.mark.parametrize(("rel", "km"), REAL_MAPS)
def test_real_carla_maps(rel: str, km: float) -> None:
    path = shared_map(rel)
    elements = read_opendrive(path)
    assert driving_km(path, elements) == pytest.approx(km, rel=0.05)
    road_map = compile_map(elements)
    assert largest_scc_share(road_map) > 0.99
    assert len(elements.road_edges) > 50
    assert road_map.lanes.in_junction.any() and not road_map.lanes.in_junction.all()


@pytest.mark.parametrize(("rel", "lights", "stops", "yields"), [
    ("carla_opendrive_2020/Town01.xodr", 36, 0, 0),
    ("carla_opendrive_2020/Town02.xodr", 24, 0, 0),
    ("carla_opendrive_2020/Town07.xodr", 17, 19, 20),
    ("carla_opendrive/Town03.xodr", 0, 0, 0),
])  # fmt: skip
def test_real_signal_counts(rel: str, lights: int, stops: int, yields: int) -> None:
    e = read_opendrive(shared_map(rel))

    def signals(items: list) -> set[str]:
        return {x.source_id.split(" (")[0] for x in items}

    assert len(signals(e.traffic_lights)) == lights
    assert len(signals([s for s in e.stop_lines if s.kind == StopKind.STOP])) == stops
    assert len(signals([s for s in e.stop_lines if s.kind == StopKind.YIELD])) == yields
    for item in e.traffic_lights + e.stop_lines:
        assert item.lanes, item.source_id
        width = float(np.hypot(*(item.points[0] - item.points[-1])))
        assert 2.0 < width < 12.0, item.source_id  # spans one to three lanes


def test_bus_and_bicycle_lanes_and_bidirectional_twins(tmp_path: Path) -> None:
    link = '<link><successor id="1"/></link>'
    body = _road(
        "8", 0, 0, 0, 40, _lane(1, "bidirectional", link=link), _lane(-1, "bus") + _lane(-2, "biking", 1.5)
    )
    e = read_opendrive(_write(tmp_path, body))
    kinds = {lane.source_id: lane.kind for lane in e.lanes}
    assert kinds["road 8/section 0/lane -1"] == LaneKind.BUS
    assert kinds["road 8/section 0/lane -2"] == LaneKind.BICYCLE
    i = _by_id(e)
    fwd, rev = i["road 8/section 0/lane 1"], i["road 8/section 0/lane 1/reverse"]
    assert (e.lanes[fwd].twin, e.lanes[rev].twin) == (rev, fwd)
    np.testing.assert_allclose(e.lanes[fwd].centerline, e.lanes[rev].centerline[::-1])
