"""Traffic lights, stop and yield lines, and crosswalks from OpenDRIVE signals and objects.

The paper (section 2.1) represents every regulatory feature as a line where a vehicle must stop.
A signal controls the lanes named by the `<validity>` records of its `<signalReference>`s (or
of the signal itself). When those lanes are connecting lanes inside a junction, the line is
drawn across the end of the lanes that lead into them, at the junction entry: "these stop lines
only span the lane entering the intersection" (paper section 4). Otherwise it is drawn across
the controlled lanes at the signal's s. Without usable validity records the lanes are those
travelling in the signal's `orientation` ("+" = increasing s), else those on the signal's side.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from selfplaydrive.errors import MapError
from selfplaydrive.maps.elements import (
    CrosswalkElement,
    LaneElement,
    StopKind,
    StopLineElement,
    TrafficLightElement,
)
from selfplaydrive.maps.opendrive.geometry import ReferenceLine
from selfplaydrive.maps.opendrive.lanes import Key, LaneIndex
from selfplaydrive.maps.opendrive.parse import OdrMap, Road, RoadObject, Signal
from selfplaydrive.maps.opendrive.sections import MAX_COORDINATE

STOP_TYPES = {"206", "r1-1"}  # OpenDRIVE / German catalogue code, US MUTCD code
YIELD_TYPES = {"205", "r1-2"}


def classify(sig: Signal) -> str | None:
    """ "light", "stop", "yield" or None (other signs are ignored)."""
    t = sig.type.strip().lower()
    if t in STOP_TYPES:
        return "stop"
    if t in YIELD_TYPES:
        return "yield"
    # 1000001..1000020 are the catalogue's traffic lights; other dynamic signals count too
    if t.startswith("1000") or sig.dynamic.strip().lower() == "yes":
        return "light"
    return None


@dataclass
class _Placement:
    road: Road
    sig: Signal


def _section_index(road: Road, s: float) -> int:
    starts = [sec.s for sec in road.sections]
    return max(0, int(np.searchsorted(starts, s, side="right")) - 1)


def _lane_ids(p: _Placement, index: LaneIndex) -> list[int]:
    """Lane ids a placement controls: validity, else orientation, else the side of the road."""
    k = _section_index(p.road, p.sig.s)
    present = [key[2] for key in index.by_key if key[0] == p.road.id and key[1] == k]
    ranges = [(min(a, b), max(a, b)) for a, b in p.sig.validity if (a, b) != (0, 0)]
    if ranges:
        return [lid for lid in present if any(lo <= lid <= hi for lo, hi in ranges)]
    want_forward = {"+": True, "-": False}.get(p.sig.orientation)
    if want_forward is None:
        want_forward = p.sig.t < 0 if p.road.rule != "LHT" else p.sig.t > 0
    return [lid for lid in present if any(f == want_forward for _, f in index.by_key[(p.road.id, k, lid)])]


def _cross_line(index: LaneIndex, keys: Iterable[Key], s: float | None, at_exit: bool) -> np.ndarray | None:
    """Line across the given lanes of one section: at road position s, or at their exit end."""
    keys = list(keys)
    g = index.geoms[keys[0][:2]]
    ups, lows = [], []
    if at_exit:
        forward = index.by_key[keys[0]][0][1]
        pos = -1 if forward else 0
        for key in keys:
            up, low = g.upper_lower(key[2])
            ups.append(up[pos])
            lows.append(low[pos])
        a = g.points(max(ups))[pos]
        b = g.points(min(lows))[pos]
    else:
        s = float(np.clip(s, g.s[0], g.s[-1]))
        for key in keys:
            up, low = g.upper_lower(key[2])
            ups.append(np.interp(s, g.s, up))
            lows.append(np.interp(s, g.s, low))
        i = int(np.clip(np.searchsorted(g.s, s), 0, len(g.s) - 1))
        x, y, h = np.interp(s, g.s, g.x), np.interp(s, g.s, g.y), g.hdg[i]
        a = np.array([x - max(ups) * np.sin(h), y + max(ups) * np.cos(h)])
        b = np.array([x - min(lows) * np.sin(h), y + min(lows) * np.cos(h)])
    if np.hypot(*(a - b)) < 1e-3:
        return None
    return np.stack([a, b])


def _lines_for(
    placements: list[_Placement], index: LaneIndex, lanes: list[LaneElement]
) -> list[tuple[np.ndarray, list[int], str]]:
    """(line points, controlled lane indices, source id) for one signal's placements."""
    at_entry: dict[tuple[str, int], set[Key]] = {}
    mid_road: list[tuple[list[Key], float]] = []
    pred_of: dict[int, list[int]] = {}
    for i, lane in enumerate(lanes):
        for j in lane.successors:
            pred_of.setdefault(j, []).append(i)
    key_of = {i: key for key, entries in index.by_key.items() for i, _ in entries}
    for p in placements:
        k = _section_index(p.road, p.sig.s)
        keys = [(p.road.id, k, lid) for lid in _lane_ids(p, index)]
        if not keys:
            continue
        if p.road.junction == "-1":
            mid_road.append((keys, p.sig.s))
            continue
        for key in keys:
            for i, _ in index.by_key[key]:
                approach = [j for j in pred_of.get(i, []) if not lanes[j].in_junction]
                for j in approach or [i]:
                    ak = key_of[j]
                    at_entry.setdefault(ak[:2], set()).add(ak)
    out = []
    for (rid, k), keys in sorted(at_entry.items()):
        line = _cross_line(index, sorted(keys), None, at_exit=True)
        controlled = sorted({i for key in keys for i, _ in index.by_key[key]})
        if line is not None:
            out.append((line, controlled, f"road {rid}/section {k}"))
    for keys, s in mid_road:
        line = _cross_line(index, keys, s, at_exit=False)
        if line is not None:
            out.append(
                (line, sorted({i for key in keys for i, _ in index.by_key[key]}), f"road {keys[0][0]}")
            )
    return out


def signal_elements(
    odr: OdrMap, refs: dict[str, ReferenceLine], index: LaneIndex, lanes: list[LaneElement]
) -> tuple[list[StopLineElement], list[TrafficLightElement]]:
    """Stop/yield lines and traffic lights of the map (groups from `<controller>`s)."""
    signals: dict[str, _Placement] = {}
    references: dict[str, list[_Placement]] = {}
    for road in odr.roads.values():
        for sig in road.signals:
            if sig.reference:
                references.setdefault(sig.id, []).append(_Placement(road, sig))
            else:
                signals.setdefault(sig.id, _Placement(road, sig))
    controller_of: dict[str, str] = {}
    for cid, sids in odr.controllers:
        for sid in sids:
            controller_of.setdefault(sid, cid)
    group_ids: dict[str, int] = {}
    stops, lights = [], []
    for sid, own in signals.items():
        kind = classify(own.sig)
        if kind is None:
            continue
        refs_ok = [p for p in references.get(sid, []) if any(v != (0, 0) for v in p.sig.validity)]
        placements = refs_ok or references.get(sid, []) or [own]
        if own.sig.validity and any(v != (0, 0) for v in own.sig.validity) and refs_ok:
            placements = [own, *refs_ok]
        for line, controlled, where in _lines_for(placements, index, lanes):
            source = f"signal {sid} ({where})"
            if kind == "light":
                group_key = controller_of.get(sid, f"signal {sid}")
                group = group_ids.setdefault(group_key, len(group_ids))
                lights.append(TrafficLightElement(line, group, controlled, source))
            else:
                stop_kind = StopKind.STOP if kind == "stop" else StopKind.YIELD
                stops.append(StopLineElement(line, stop_kind, controlled, source))
    return stops, lights


def _object_polygons(obj: RoadObject, ref: ReferenceLine) -> list[np.ndarray]:
    def road_xy(s: np.ndarray, t: np.ndarray) -> np.ndarray:
        x, y, h = ref.evaluate(np.asarray(s, dtype=np.float64))
        return np.stack([x - t * np.sin(h), y + t * np.cos(h)], axis=1)

    x0, y0, h0 = ref.evaluate(np.array([obj.s]))
    origin = np.array([x0[0] - obj.t * np.sin(h0[0]), y0[0] + obj.t * np.cos(h0[0])])
    heading = h0[0] + obj.hdg
    rot = np.array([[np.cos(heading), -np.sin(heading)], [np.sin(heading), np.cos(heading)]])
    polys = [origin + np.asarray(uv) @ rot.T for uv in obj.outlines_local]
    polys += [road_xy(np.array([p[0] for p in st]), np.array([p[1] for p in st])) for st in obj.outlines_road]
    for rep in obj.repeats:
        if polys or rep["length"] <= 0:
            continue
        s = np.linspace(rep["s"], rep["s"] + rep["length"], 16)
        f = (s - s[0]) / rep["length"]
        t = rep["tStart"] + f * (rep["tEnd"] - rep["tStart"])
        w = 0.5 * (rep["widthStart"] + f * (rep["widthEnd"] - rep["widthStart"]))
        polys.append(np.concatenate([road_xy(s, t + w), road_xy(s, t - w)[::-1]]))
    if not polys and obj.length > 0 and obj.width > 0:
        u, v = 0.5 * obj.length, 0.5 * obj.width
        polys.append(origin + np.array([[u, v], [-u, v], [-u, -v], [u, -v]]) @ rot.T)
    return polys


def crosswalks(odr: OdrMap, refs: dict[str, ReferenceLine]) -> list[CrosswalkElement]:
    """Polygons of `<object type="crosswalk">` (outline, repeat, or length x width box)."""
    out = []
    for road in odr.roads.values():
        for obj in road.objects:
            if obj.type.lower() != "crosswalk":
                continue
            for k, poly in enumerate(_object_polygons(obj, refs[road.id])):
                if len(poly) > 1 and np.allclose(poly[0], poly[-1]):
                    poly = poly[:-1]
                if not np.all(np.abs(poly) < MAX_COORDINATE):
                    raise MapError(
                        "crosswalk outline is not finite or too far away",
                        refs[road.id].path,
                        f"road {road.id}/object {obj.id}",
                    )
                if len(poly) >= 3:
                    out.append(
                        CrosswalkElement(poly, f"road {road.id}/object {obj.id}" + (f"/{k}" if k else ""))
                    )
    return out
