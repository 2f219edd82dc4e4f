"""Read the OSM XML container of a Lanelet2 map into plain, validated Python structures.

Only the standard library parser is used (`xml.etree.ElementTree`). Every problem
(malformed XML, a missing or non-numeric id or coordinate, NaN, duplicate ids, a way or relation
member that points at nothing) raises `MapError` naming the file and the element.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from selfplaydrive.errors import MapError
from selfplaydrive.maps.projection import LocalTransverseMercator, lest97

# Tartu's local_x/local_y are L-EST97 minus this offset (measured, /work/shared/maps/README.md)
TARTU_LEST97_OFFSET = (650000.0, 6465000.0)
MAX_LOCAL_COORD = 1e8  # [m] larger local coordinates are corrupt (Earth's circumference is 4e7 m)
# [m] Lanelet2 maps are local (Tartu's demo spans 3.2 km); a wider spread of the nodes that make
# geometry means a mistyped coordinate, which would otherwise compile into a lane hundreds of
# km long and a segment grid of gigabytes (same bound as OpenDRIVE's MAX_EXTENT)
MAX_EXTENT = 1.0e5
LEST97_MATCH_TOL = 1.0  # [m] local + offset must agree with the projected lat/lon this well


@dataclass
class Way:
    """An OSM way: node ids in order and normalised tags."""

    id: int
    nodes: list[int]
    tags: dict[str, str]


@dataclass
class Member:
    """A relation member: `type` is "node", "way" or "relation"."""

    type: str
    ref: int
    role: str


@dataclass
class Relation:
    """An OSM relation: members and normalised tags."""

    id: int
    members: list[Member]
    tags: dict[str, str]

    def ways(self, role: str) -> list[int]:
        """Ids of the way members with this role."""
        return [m.ref for m in self.members if m.type == "way" and m.role == role]

    def relations(self, role: str | None = None) -> list[int]:
        """Ids of the relation members (with this role, if given)."""
        return [m.ref for m in self.members if m.type == "relation" and (role is None or m.role == role)]


@dataclass
class OsmData:
    """Parsed file: node ids -> row in `xy`, ways, relations, and the coordinate frame.

    Attributes:
        xy: (num_nodes, 2) float64 planar node positions [m].
        node_row: Node id -> row of `xy`.
        frame_origin: Global coordinates of the planar frame's (0, 0) [m].
        crs: Description of the global coordinate system.
    """

    path: str
    xy: np.ndarray
    node_row: dict[int, int]
    ways: dict[int, Way] = field(default_factory=dict)
    relations: dict[int, Relation] = field(default_factory=dict)
    frame_origin: tuple[float, float] = (0.0, 0.0)
    crs: str = "local"

    def way_xy(self, way_id: int) -> np.ndarray:
        """(n, 2) float64 positions of a way's nodes [m]."""
        return self.xy[[self.node_row[n] for n in self.ways[way_id].nodes]]


def norm_value(value: str | None) -> str:
    """Normalise a tag value: strip whitespace, lower-case ("bus_lane " -> "bus_lane")."""
    return (value or "").strip().lower()


def _int_attr(elem: ET.Element, key: str, path: str, what: str) -> int:
    raw = elem.get(key)
    try:
        return int(raw)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise MapError(
            f"{what} has {key}={raw!r}, expected an integer", path, f"{what} {elem.get('id')}"
        ) from None


def _float(raw: str | None, path: str, element: str, key: str) -> float:
    try:
        value = float(raw)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise MapError(f"{key}={raw!r} is not a number", path, element) from None
    if not math.isfinite(value):
        raise MapError(f"{key}={raw!r} is not finite; expected a finite coordinate", path, element)
    return value


def _tags(elem: ET.Element) -> dict[str, str]:
    # keys keep their case (Lanelet2 keys are lower case); values are normalised
    return {(t.get("k") or "").strip(): norm_value(t.get("v")) for t in elem.iter("tag")}


class _Reader:
    """Collects nodes, ways and relations from an iterparse stream."""

    def __init__(self, path: str) -> None:
        self.path = path
        self.ids: list[int] = []
        self.latlon: list[tuple[float, float] | None] = []
        self.local: list[tuple[float, float] | None] = []
        self.node_row: dict[int, int] = {}
        self.ways: dict[int, Way] = {}
        self.relations: dict[int, Relation] = {}

    def node(self, elem: ET.Element) -> None:
        nid = _int_attr(elem, "id", self.path, "node")
        name = f"node {nid}"
        if nid in self.node_row:
            raise MapError("duplicate node id", self.path, name)
        tags = {(t.get("k") or "").strip(): t.get("v") for t in elem.iter("tag")}
        ll = None
        if elem.get("lat") is not None or elem.get("lon") is not None:
            lat = _float(elem.get("lat"), self.path, name, "lat")
            lon = _float(elem.get("lon"), self.path, name, "lon")
            if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
                raise MapError(f"lat={lat}, lon={lon} out of range [-90, 90] x [-180, 180]", self.path, name)
            ll = (lat, lon)
        loc = None
        if "local_x" in tags or "local_y" in tags:
            loc = (
                _float(tags.get("local_x"), self.path, name, "local_x"),
                _float(tags.get("local_y"), self.path, name, "local_y"),
            )
        if ll is None and loc is None:
            raise MapError("node has neither lat/lon nor local_x/local_y", self.path, name)
        self.node_row[nid] = len(self.ids)
        self.ids.append(nid)
        self.latlon.append(ll)
        self.local.append(loc)

    def way(self, elem: ET.Element) -> None:
        wid = _int_attr(elem, "id", self.path, "way")
        if wid in self.ways:
            raise MapError("duplicate way id", self.path, f"way {wid}")
        nodes = [_int_attr(nd, "ref", self.path, f"way {wid} nd") for nd in elem.iter("nd")]
        self.ways[wid] = Way(wid, nodes, _tags(elem))

    def relation(self, elem: ET.Element) -> None:
        rid = _int_attr(elem, "id", self.path, "relation")
        if rid in self.relations:
            raise MapError("duplicate relation id", self.path, f"relation {rid}")
        members = []
        for m in elem.iter("member"):
            mtype = (m.get("type") or "").strip()
            if mtype not in ("node", "way", "relation"):
                raise MapError(
                    f"member type {mtype!r}, expected node, way or relation", self.path, f"relation {rid}"
                )
            ref = _int_attr(m, "ref", self.path, f"relation {rid} member")
            members.append(Member(mtype, ref, (m.get("role") or "").strip()))
        self.relations[rid] = Relation(rid, members, _tags(elem))


def _parse(path: str) -> _Reader:
    reader = _Reader(path)
    handlers = {"node": reader.node, "way": reader.way, "relation": reader.relation}
    try:
        # the whole tree is built by the C parser: faster than iterparse for city-sized maps
        root = ET.parse(path).getroot()
    except ET.ParseError as err:
        where = f"line {err.position[0]}"
        raise MapError(f"malformed XML ({err}); expected a complete OSM XML file", path, where) from None
    except OSError as err:
        raise MapError(f"cannot read the file: {err}", path) from None
    if root.tag != "osm":
        raise MapError(f"root element is <{root.tag}>, expected <osm>", path)
    for elem in root:
        # JOSM marks deleted objects with action="delete": they are not part of the map
        if elem.tag in handlers and elem.get("action") != "delete":
            handlers[elem.tag](elem)
    return reader


def _check_refs(r: _Reader) -> None:
    for way in r.ways.values():
        for n in way.nodes:
            if n not in r.node_row:
                raise MapError(f"way refers to node {n}, which is not in the file", r.path, f"way {way.id}")
    for rel in r.relations.values():
        for m in rel.members:
            known = {"node": r.node_row, "way": r.ways, "relation": r.relations}[m.type]
            if m.ref not in known:
                raise MapError(
                    f"relation member (role {m.role!r}) refers to {m.type} {m.ref}, which is not in the file",
                    r.path,
                    f"relation {rel.id}",
                )


def _project(r: _Reader) -> tuple[np.ndarray, tuple[float, float], str]:
    """Planar positions: local_x/local_y when every node has them, else a projection of lat/lon."""
    if not r.ids:
        raise MapError("the file has no nodes; expected a Lanelet2 map", r.path)
    has_local = all(v is not None for v in r.local)
    has_ll = all(v is not None for v in r.latlon)
    if has_local:
        xy = np.array(r.local, dtype=np.float64)
        far = np.flatnonzero(np.abs(xy).max(axis=1) > MAX_LOCAL_COORD)
        if len(far):
            raise MapError(
                f"local_x/local_y {tuple(xy[far[0]])} beyond +-{MAX_LOCAL_COORD:g} m; "
                "expected map-local metres",
                r.path,
                f"node {r.ids[far[0]]}",
            )
        if has_ll:
            ll = np.array(r.latlon, dtype=np.float64)
            sample = np.linspace(0, len(ll) - 1, min(len(ll), 50)).astype(int)
            est = lest97(ll[sample, 0], ll[sample, 1]) - TARTU_LEST97_OFFSET
            if np.max(np.hypot(*(est - xy[sample]).T)) < LEST97_MATCH_TOL:
                return xy, TARTU_LEST97_OFFSET, "EPSG:3301 (L-EST97 Estonian grid)"
        return xy, (0.0, 0.0), "local_x/local_y of the file (datum unknown)"
    if not has_ll:
        missing = next(i for i, v in enumerate(r.latlon) if v is None)
        raise MapError(
            "node has local_x/local_y but no lat/lon while other nodes lack local_x/local_y; "
            "expected one coordinate system for all nodes",
            r.path,
            f"node {r.ids[missing]}",
        )
    ll = np.array(r.latlon, dtype=np.float64)
    lat0 = float((ll[:, 0].min() + ll[:, 0].max()) / 2)
    lon0 = float((ll[:, 1].min() + ll[:, 1].max()) / 2)
    tm = LocalTransverseMercator(lat0, lon0)
    return tm.forward(ll[:, 0], ll[:, 1]), (0.0, 0.0), tm.crs


def _geometry_rows(r: _Reader) -> np.ndarray:
    """Rows of `xy` of the nodes that can become geometry: way nodes and relation node members
    (a node that nothing refers to never reaches the compiled map)."""
    ids = {n for way in r.ways.values() for n in way.nodes}
    ids.update(m.ref for rel in r.relations.values() for m in rel.members if m.type == "node")
    return np.fromiter(sorted(r.node_row[n] for n in ids), dtype=np.int64, count=len(ids))


def _check_extent(r: _Reader, xy: np.ndarray) -> None:
    """Raise MapError naming the node farthest from the median node if the nodes used by ways
    and relations spread wider than `MAX_EXTENT` in x or y."""
    rows = _geometry_rows(r)
    if len(rows) == 0:
        return
    pts = xy[rows]
    span = np.ptp(pts, axis=0)
    if np.all(span <= MAX_EXTENT):
        return
    # the median is robust to the few corrupt nodes, so the farthest node is the culprit
    far = rows[int(np.argmax(np.abs(pts - np.median(pts, axis=0)).max(axis=1)))]
    raise MapError(
        f"the map's nodes span {span.max():.3g} m, more than {MAX_EXTENT:g} m; this node at "
        f"({xy[far, 0]:.6g}, {xy[far, 1]:.6g}) [m] lies farthest from the rest (mistyped "
        "coordinate?); expected a local map",
        r.path,
        f"node {r.ids[far]}",
    )


def read_osm(path: str | Path) -> OsmData:
    """Parse an OSM XML file, check its references and project its nodes to metres.

    Args:
        path: The .osm file.

    Returns:
        `OsmData` with planar node positions [m].

    Raises:
        MapError: Malformed XML, bad numbers, duplicate ids, dangling references, or nodes
            spread wider than `MAX_EXTENT` (the message names the farthest node).
    """
    spath = str(path)
    reader = _parse(spath)
    _check_refs(reader)
    xy, origin, crs = _project(reader)
    _check_extent(reader, xy)
    return OsmData(spath, xy, reader.node_row, reader.ways, reader.relations, origin, crs)
