"""Parse an OpenDRIVE (.xodr) file into plain dataclasses, with strict attribute checks.

Only the parts the loader uses are kept (paper section 2.1: lanes, road edges, traffic lights,
stop/yield lines, crosswalks). Every numeric attribute is checked for presence and finiteness
here, so the geometry code downstream never sees NaN, and every error names the file and the
element (road id, lane id, signal id ...) that is wrong.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

from selfplaydrive.errors import MapError

GEOMETRY_KINDS = ("line", "arc", "spiral", "poly3", "paramPoly3")
MAX_ROAD_LENGTH = 1.0e6  # [m] beyond this a length is treated as corrupt (guards memory use)
SPEED_UNITS = {"m/s": 1.0, "km/h": 1.0 / 3.6, "mph": 0.44704}


@dataclass
class Poly:
    """Cubic a + b*ds + c*ds^2 + d*ds^3 starting at `s` (absolute or section-relative) [m]."""

    s: float
    a: float
    b: float = 0.0
    c: float = 0.0
    d: float = 0.0


@dataclass
class Geometry:
    """One `<geometry>` record of the plan view. `params` holds the kind's attributes."""

    s: float
    x: float
    y: float
    hdg: float
    length: float
    kind: str
    params: dict[str, float | str] = field(default_factory=dict)


@dataclass
class RoadMark:
    """A `<roadMark>`: section-relative start `s_offset` [m], `type`, `lane_change` ("" if absent)."""

    s_offset: float
    type: str
    lane_change: str = ""


@dataclass
class Lane:
    """One `<lane>` of a lane section. Widths are section-relative polynomials."""

    id: int
    type: str
    widths: list[Poly] = field(default_factory=list)
    borders: list[Poly] = field(default_factory=list)
    marks: list[RoadMark] = field(default_factory=list)
    predecessors: list[int] = field(default_factory=list)
    successors: list[int] = field(default_factory=list)
    has_link: bool = False
    speeds: list[tuple[float, float]] = field(default_factory=list)  # (sOffset [m], max [m/s])
    direction: str = "standard"


@dataclass
class LaneSection:
    """A `<laneSection>`: start `s` [m], lanes keyed by id (0 is the centre lane), and its end."""

    s: float
    lanes: dict[int, Lane]
    s_end: float = 0.0


@dataclass
class RoadLink:
    """A road `<predecessor>`/`<successor>`: element type ("road"/"junction"), id, contact point."""

    element_type: str
    element_id: str
    contact_point: str = ""


@dataclass
class Signal:
    """A `<signal>` or `<signalReference>` (then `reference` is True and type fields are empty)."""

    id: str
    s: float
    t: float
    orientation: str
    type: str = ""
    subtype: str = ""
    dynamic: str = ""
    name: str = ""
    validity: list[tuple[int, int]] = field(default_factory=list)
    reference: bool = False


@dataclass
class RoadObject:
    """An `<object>`: position (s, t) [m], heading offset `hdg` [rad], size [m], outlines."""

    id: str
    type: str
    name: str
    s: float
    t: float
    hdg: float
    length: float
    width: float
    outlines_local: list[list[tuple[float, float]]] = field(default_factory=list)  # (u, v) [m]
    outlines_road: list[list[tuple[float, float]]] = field(default_factory=list)  # (s, t) [m]
    repeats: list[dict[str, float]] = field(default_factory=list)


@dataclass
class Road:
    """One `<road>`."""

    id: str
    length: float
    junction: str
    rule: str
    geometries: list[Geometry]
    lane_offsets: list[Poly]
    sections: list[LaneSection]
    predecessor: RoadLink | None = None
    successor: RoadLink | None = None
    speeds: list[tuple[float, float | None]] = field(default_factory=list)  # (s [m], max [m/s])
    signals: list[Signal] = field(default_factory=list)
    objects: list[RoadObject] = field(default_factory=list)


@dataclass
class Connection:
    """A junction `<connection>` and its `<laneLink from to>` pairs."""

    id: str
    incoming: str
    connecting: str
    contact_point: str
    lane_links: list[tuple[int, int]] = field(default_factory=list)


@dataclass
class OdrMap:
    """The parsed file."""

    path: str
    roads: dict[str, Road]
    junctions: dict[str, list[Connection]]
    controllers: list[tuple[str, list[str]]]  # (controller id, controlled signal ids)


class _Reader:
    """Attribute access that raises `MapError` naming the file and the element."""

    def __init__(self, path: str) -> None:
        self.path = path

    def err(self, message: str, element: str | None) -> MapError:
        return MapError(message, self.path, element)

    def num(self, el: ET.Element, name: str, where: str, default: float | None = None) -> float:
        raw = el.get(name)
        if raw is None:
            if default is None:
                raise self.err(f"<{el.tag}> is missing required attribute '{name}' (a number)", where)
            return default
        try:
            v = float(raw)
        except ValueError:
            raise self.err(f"<{el.tag}> attribute {name}={raw!r} is not a number", where) from None
        if not math.isfinite(v):
            raise self.err(f"<{el.tag}> attribute {name}={raw!r} must be finite", where)
        return v

    def int_(self, el: ET.Element, name: str, where: str) -> int:
        v = self.num(el, name, where)
        if v != int(v):
            raise self.err(f"<{el.tag}> attribute {name}={el.get(name)!r} must be an integer", where)
        return int(v)

    def text(self, el: ET.Element, name: str, where: str, default: str | None = None) -> str:
        raw = el.get(name)
        if raw is None:
            if default is None:
                raise self.err(f"<{el.tag}> is missing required attribute '{name}'", where)
            return default
        return raw.strip()

    def poly(self, el: ET.Element, s_name: str, where: str) -> Poly:
        return Poly(
            s=self.num(el, s_name, where),
            a=self.num(el, "a", where),
            b=self.num(el, "b", where, 0.0),
            c=self.num(el, "c", where, 0.0),
            d=self.num(el, "d", where, 0.0),
        )


def _geometry(r: _Reader, el: ET.Element, where: str) -> Geometry:
    head = {k: r.num(el, k, where) for k in ("s", "x", "y", "hdg", "length")}
    if not 0.0 <= head["length"] <= MAX_ROAD_LENGTH:
        raise r.err(f"geometry length={head['length']} must be in [0, {MAX_ROAD_LENGTH:g}] m", where)
    kids = [k for k in el if k.tag not in ("userData", "include", "dataQuality")]
    if len(kids) != 1:
        tags = [k.tag for k in kids]
        raise r.err(f"<geometry> at s={head['s']} needs exactly one of {GEOMETRY_KINDS}, got {tags}", where)
    k = kids[0]
    if k.tag not in GEOMETRY_KINDS:
        raise r.err(f"unsupported geometry <{k.tag}> at s={head['s']}; supported: {GEOMETRY_KINDS}", where)
    params: dict[str, float | str] = {}
    if k.tag == "arc":
        params["curvature"] = r.num(k, "curvature", where)
    elif k.tag == "spiral":
        params["curvStart"] = r.num(k, "curvStart", where)
        params["curvEnd"] = r.num(k, "curvEnd", where)
    elif k.tag == "poly3":
        params.update({n: r.num(k, n, where) for n in "abcd"})
    elif k.tag == "paramPoly3":
        for n in ("aU", "bU", "cU", "dU", "aV", "bV", "cV", "dV"):
            params[n] = r.num(k, n, where)
        p_range = r.text(k, "pRange", where, "normalized")
        if p_range not in ("normalized", "arcLength"):
            raise r.err(f"paramPoly3 pRange={p_range!r}, expected 'normalized' or 'arcLength'", where)
        params["pRange"] = p_range
    return Geometry(kind=k.tag, params=params, **head)


def _speed(r: _Reader, el: ET.Element, where: str) -> float | None:
    raw = (el.get("max") or "").strip().lower()
    if raw in ("", "no limit", "undefined", "none"):
        return None
    unit = r.text(el, "unit", where, "m/s")
    if unit not in SPEED_UNITS:
        raise r.err(f"speed unit={unit!r}, expected one of {sorted(SPEED_UNITS)}", where)
    v = r.num(el, "max", where) * SPEED_UNITS[unit]
    if v <= 0:
        raise r.err(f"speed max={raw!r} must be positive", where)
    return v


def _lane(r: _Reader, el: ET.Element, road_where: str) -> Lane:
    lid = r.int_(el, "id", road_where)
    where = f"{road_where}/lane {lid}"
    lane = Lane(id=lid, type=r.text(el, "type", where, "none"), direction=el.get("direction", "standard"))
    lane.widths = sorted((r.poly(w, "sOffset", where) for w in el.findall("width")), key=lambda p: p.s)
    lane.borders = sorted((r.poly(w, "sOffset", where) for w in el.findall("border")), key=lambda p: p.s)
    for m in el.findall("roadMark"):
        lane.marks.append(
            RoadMark(
                r.num(m, "sOffset", where, 0.0), r.text(m, "type", where, "none"), m.get("laneChange", "")
            )
        )
    lane.marks.sort(key=lambda m: m.s_offset)
    link = el.find("link")
    if link is not None:
        lane.has_link = True
        lane.predecessors = [r.int_(p, "id", where) for p in link.findall("predecessor")]
        lane.successors = [r.int_(p, "id", where) for p in link.findall("successor")]
    for sp in el.findall("speed"):
        v = _speed(r, sp, where)
        if v is not None:
            lane.speeds.append((r.num(sp, "sOffset", where, 0.0), v))
    return lane


def _sections(r: _Reader, lanes_el: ET.Element, where: str, length: float) -> list[LaneSection]:
    sections = []
    for i, sec in enumerate(lanes_el.findall("laneSection")):
        sw = f"{where}/laneSection {i}"
        lanes: dict[int, Lane] = {}
        for side in ("left", "center", "right"):
            for side_el in sec.findall(side):
                for lane_el in side_el.findall("lane"):
                    lane = _lane(r, lane_el, sw)
                    if lane.id in lanes:
                        raise r.err(f"duplicate lane id {lane.id}", sw)
                    if (side == "left" and lane.id <= 0) or (side == "right" and lane.id >= 0):
                        raise r.err(f"lane id {lane.id} is on the wrong side (<{side}>)", sw)
                    lanes[lane.id] = lane
        sections.append(LaneSection(s=r.num(sec, "s", sw), lanes=lanes))
    if not sections:
        raise r.err("road has no <laneSection>", where)
    sections.sort(key=lambda x: x.s)
    for a, b in zip(sections, [*sections[1:], None], strict=True):
        a.s_end = length if b is None else b.s
    return sections


def _link(r: _Reader, el: ET.Element | None, where: str) -> RoadLink | None:
    if el is None:
        return None
    return RoadLink(
        r.text(el, "elementType", where, "road"),
        r.text(el, "elementId", where),
        el.get("contactPoint", ""),
    )


def _signals(r: _Reader, road_el: ET.Element, where: str) -> list[Signal]:
    out = []
    for sigs in road_el.findall("signals"):
        for el in list(sigs):
            if el.tag not in ("signal", "signalReference"):
                continue
            sid = r.text(el, "id", where)
            sw = f"{where}/{el.tag} {sid}"
            sig = Signal(
                id=sid,
                s=r.num(el, "s", sw),
                t=r.num(el, "t", sw, 0.0),
                orientation=el.get("orientation", "none"),
                reference=el.tag == "signalReference",
            )
            if not sig.reference:
                sig.type = r.text(el, "type", sw, "-1")
                sig.subtype = el.get("subtype", "-1")
                sig.dynamic = el.get("dynamic", "no")
                sig.name = el.get("name", "")
            sig.validity = [
                (r.int_(v, "fromLane", sw), r.int_(v, "toLane", sw)) for v in el.findall("validity")
            ]
            out.append(sig)
    return out


def _outline_points(r: _Reader, outline: ET.Element, where: str) -> tuple[list, list]:
    local = [(r.num(c, "u", where), r.num(c, "v", where)) for c in outline.findall("cornerLocal")]
    road = [(r.num(c, "s", where), r.num(c, "t", where)) for c in outline.findall("cornerRoad")]
    return local, road


def _objects(r: _Reader, road_el: ET.Element, where: str) -> list[RoadObject]:
    out = []
    for objs in road_el.findall("objects"):
        for el in objs.findall("object"):
            oid = r.text(el, "id", where)
            ow = f"{where}/object {oid}"
            obj = RoadObject(
                id=oid,
                type=el.get("type", "").strip(),
                name=el.get("name", ""),
                s=r.num(el, "s", ow),
                t=r.num(el, "t", ow),
                hdg=r.num(el, "hdg", ow, 0.0),
                length=r.num(el, "length", ow, 0.0),
                width=r.num(el, "width", ow, 0.0),
            )
            for outline in el.findall("outline") + el.findall("outlines/outline"):
                local, road = _outline_points(r, outline, ow)
                if local:
                    obj.outlines_local.append(local)
                if road:
                    obj.outlines_road.append(road)
            for rep in el.findall("repeat"):
                obj.repeats.append(
                    {
                        k: r.num(rep, k, ow, 0.0)
                        for k in ("s", "length", "distance", "tStart", "tEnd", "widthStart", "widthEnd")
                    }
                )
            out.append(obj)
    return out


def _road(r: _Reader, el: ET.Element, default_rule: str) -> Road:
    rid = r.text(el, "id", "road ?")
    where = f"road {rid}"
    length = r.num(el, "length", where)
    if not 0.0 < length <= MAX_ROAD_LENGTH:
        raise r.err(f"road length={length} must be in (0, {MAX_ROAD_LENGTH:g}] m", where)
    plan = el.find("planView")
    geoms = [] if plan is None else [_geometry(r, g, where) for g in plan.findall("geometry")]
    if not geoms:
        raise r.err("road has no <planView><geometry>", where)
    geoms.sort(key=lambda g: g.s)
    lanes_el = el.find("lanes")
    if lanes_el is None:
        raise r.err("road has no <lanes>", where)
    offsets = sorted((r.poly(o, "s", where) for o in lanes_el.findall("laneOffset")), key=lambda p: p.s)
    rule = r.text(el, "rule", where, default_rule).upper()
    if rule not in ("RHT", "LHT"):
        raise r.err(f"rule={rule!r}, expected 'RHT' or 'LHT'", where)
    road = Road(
        id=rid,
        length=length,
        junction=r.text(el, "junction", where, "-1"),
        rule=rule,
        geometries=geoms,
        lane_offsets=offsets,
        sections=_sections(r, lanes_el, where, length),
    )
    link = el.find("link")
    if link is not None:
        road.predecessor = _link(r, link.find("predecessor"), where)
        road.successor = _link(r, link.find("successor"), where)
    for t in el.findall("type"):
        s = r.num(t, "s", where, 0.0)
        sp = t.find("speed")
        road.speeds.append((s, None if sp is None else _speed(r, sp, where)))
    road.speeds.sort(key=lambda x: x[0])
    road.signals = _signals(r, el, where)
    road.objects = _objects(r, el, where)
    return road


def _junction(r: _Reader, el: ET.Element) -> tuple[str, list[Connection]]:
    jid = r.text(el, "id", "junction ?")
    conns = []
    for c in el.findall("connection"):
        cw = f"junction {jid}/connection {c.get('id', '?')}"
        conn = Connection(
            id=c.get("id", ""),
            incoming=r.text(c, "incomingRoad", cw),
            connecting=r.text(c, "connectingRoad", cw),
            contact_point=r.text(c, "contactPoint", cw, "start"),
        )
        conn.lane_links = [(r.int_(ll, "from", cw), r.int_(ll, "to", cw)) for ll in c.findall("laneLink")]
        conns.append(conn)
    return jid, conns


def parse_opendrive(path: str | Path) -> OdrMap:
    """Read and check an .xodr file.

    Raises:
        MapError: Unreadable or truncated XML, a root other than <OpenDRIVE>, missing or
            non-finite required attributes, unsupported geometry, duplicate road ids, no roads.
    """
    path = str(path)
    r = _Reader(path)
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as e:
        raise MapError(f"not well-formed XML (truncated or corrupt file?): {e}", path) from None
    except OSError as e:
        raise MapError(f"cannot read file: {e}", path) from None
    if root.tag != "OpenDRIVE":
        raise MapError(f"root element is <{root.tag}>, expected <OpenDRIVE>", path)
    header = root.find("header")
    default_rule = "RHT"
    if header is not None and header.get("rule"):
        default_rule = header.get("rule", "RHT").strip().upper()
    roads: dict[str, Road] = {}
    for el in root.findall("road"):
        road = _road(r, el, default_rule)
        if road.id in roads:
            raise r.err("duplicate road id", f"road {road.id}")
        roads[road.id] = road
    if not roads:
        raise MapError("map has no <road> elements", path)
    junctions = dict(_junction(r, el) for el in root.findall("junction"))
    controllers = [
        (c.get("id", ""), [cc.get("signalId", "") for cc in c.findall("control")])
        for c in root.findall("controller")
    ]
    return OdrMap(path=path, roads=roads, junctions=junctions, controllers=controllers)
