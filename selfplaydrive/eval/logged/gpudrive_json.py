"""Loader of logged scenarios in the GPUDrive / Nocturne JSON layout (converted WOMD scenes).

What is read (everything else is ignored; no Waymo-derived file ships with the library):

- ``objects``: list; each object needs ``position`` (list of {"x", "y"[, "z"]}), ``heading``
  (list of numbers), ``velocity`` (list of {"x", "y"}), ``valid`` (list of bool/0/1), all of the
  same length T (91 steps at 10 Hz for WOMD), plus ``width`` and ``length`` [m] and ``type``
  ("vehicle", "pedestrian", "cyclist"; anything else is kept as "other" and only counts as a
  collision partner). ``id`` and ``goalPosition`` are optional. Positions of invalid steps are
  ignored (the converters write -10000 there).
- ``heading`` units: radians, or degrees (Nocturne-era files); ``heading_unit="auto"`` takes
  degrees when some valid |heading| exceeds 2 pi + 0.5.
- ``roads``: list of {"type", "geometry": [{"x", "y"}...]}; ``lane`` polylines become lanes
  (width `lane_width`, speed limit ``speed_limit_mph`` when present else `speed_limit`), with
  successors inferred geometrically (a lane whose start lies within `connect_tol` of another's
  end, heading change below 60 deg), since the layout has no lane graph; ``road_edge`` becomes a
  road edge (simulator contact) and, as is, an oriented edge of the Waymax off-road metric
  (drivable area on its left, WOMD's convention); ``crosswalk`` polygons become crosswalks.
  ``road_line``, ``stop_sign`` (a point, not a line), ``speed_bump``, ``driveway`` are not used.
  Lanes or edges with fewer than 2 distinct points are skipped and counted in `skipped`.
- ``tl_states``: not read (GPUDrive's own reader ignores it; converted files leave it empty),
  so logged scenarios run without traffic lights.
- ``metadata.sdc_track_index``: the ego (self-driving car) when present and a valid vehicle at
  the start step; otherwise the first vehicle valid at the start step.

Coordinates: the map is compiled with `compile_map`, which recentres it; every track is shifted
by the same offset (`LoggedScenario.shift`) so tracks and map share the map-local frame.
Malformed files raise `MapError` naming the file and the field (e.g. ``objects[3].velocity``).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from selfplaydrive.errors import MapError
from selfplaydrive.maps.compile import compile_map
from selfplaydrive.maps.elements import CrosswalkElement, EdgeKind, LaneElement, MapElements, PolylineElement
from selfplaydrive.maps.roadmap import RoadMap

__all__ = ["LoggedScenario", "load_gpudrive_json"]

MPH = 0.44704  # [m/s] per mile per hour


@dataclass
class LoggedScenario:
    """A logged scene: compiled map plus object tracks in the map-local frame.

    Attributes:
        name: File stem (or ``name``/``scenario_id`` field).
        path: Source file.
        road_map: The compiled `RoadMap`.
        shift: (2,) float64 [m] subtracted from file coordinates (map recentring).
        xy: (N, T, 2) float64 [m] positions (0 at invalid steps).
        heading: (N, T) float64 [rad].
        vel: (N, T, 2) float64 [m/s].
        valid: (N, T) bool.
        length: (N,) float64 [m].
        width: (N,) float64 [m].
        kind: (N,) str "vehicle", "pedestrian", "cyclist" or "other".
        object_id: (N,) int64 (the index when the file has no ids).
        sdc: Index of the file's self-driving car, or -1 when not given.
        edges: Oriented road-edge polylines [(n, 2) float64, map-local] for the off-road metric.
        dt: Step length [s] (0.1, WOMD's 10 Hz).
        skipped: Counts of road elements not used, by reason.
    """

    name: str
    path: str
    road_map: RoadMap
    shift: np.ndarray
    xy: np.ndarray
    heading: np.ndarray
    vel: np.ndarray
    valid: np.ndarray
    length: np.ndarray
    width: np.ndarray
    kind: np.ndarray
    object_id: np.ndarray
    sdc: int
    edges: list[np.ndarray]
    dt: float = 0.1
    skipped: dict[str, int] = field(default_factory=dict)

    @property
    def num_steps(self) -> int:
        return self.xy.shape[1]

    def ego_index(self, start: int = 10) -> int:
        """The SDC if it is a vehicle valid at `start`, else the first such vehicle.

        Raises:
            ValueError: When no vehicle is valid at `start`.
        """
        ok = (self.kind == "vehicle") & self.valid[:, start]
        if 0 <= self.sdc < len(ok) and ok[self.sdc]:
            return self.sdc
        if not ok.any():
            raise ValueError(f"{self.path}: no vehicle is valid at step {start}; nothing to drive")
        return int(np.flatnonzero(ok)[0])


def _get(obj: Any, key: str, path: str, where: str) -> Any:
    if not isinstance(obj, dict) or key not in obj:
        raise MapError(
            f"missing field '{where}.{key}'" if where else f"missing field '{key}'", path, where or None
        )
    return obj[key]


def _num(v: Any, path: str, where: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)):
        raise MapError(f"{where}: expected a finite number, got {v!r}", path, where)
    return float(v)


def _points(items: Any, path: str, where: str) -> np.ndarray:
    if not isinstance(items, list):
        raise MapError(
            f"{where}: expected a list of {{x, y}} points, got {type(items).__name__}", path, where
        )
    out = np.empty((len(items), 2))
    for k, p in enumerate(items):
        out[k] = (_num(_get(p, "x", path, f"{where}[{k}]"), path, f"{where}[{k}].x"),
                  _num(_get(p, "y", path, f"{where}[{k}]"), path, f"{where}[{k}].y"))  # fmt: skip
    return out


def _series(items: Any, n: int | None, path: str, where: str) -> list:
    if not isinstance(items, list):
        raise MapError(f"{where}: expected a list, got {type(items).__name__}", path, where)
    if n is not None and len(items) != n:
        raise MapError(
            f"{where}: expected {n} entries (one per step, like position), got {len(items)}", path, where
        )
    return items


def _object(o: Any, i: int, T: int | None, path: str) -> dict[str, Any]:
    w = f"objects[{i}]"
    pos = _series(_get(o, "position", path, w), T, path, f"{w}.position")
    T = len(pos)
    valid = np.array(
        [bool(v) if isinstance(v, (bool, int)) else _bad(v, path, f"{w}.valid")
         for v in _series(_get(o, "valid", path, w), T, path, f"{w}.valid")], dtype=bool)  # fmt: skip
    heading = np.array(
        [_num(h, path, f"{w}.heading") for h in _series(_get(o, "heading", path, w), T, path, f"{w}.heading")]
    )
    vel = _points(_series(_get(o, "velocity", path, w), T, path, f"{w}.velocity"), path, f"{w}.velocity")
    size = [_num(_get(o, k, path, w), path, f"{w}.{k}") for k in ("length", "width")]
    if valid.any() and min(size) <= 0:
        raise MapError(f"{w}: length and width must be positive [m], got {size}", path, w)
    kind = _get(o, "type", path, w)
    if not isinstance(kind, str):
        raise MapError(f"{w}.type: expected a string, got {kind!r}", path, f"{w}.type")
    return {
        "xy": _points(pos, path, f"{w}.position"),
        "heading": heading,
        "vel": vel,
        "valid": valid,
        "length": size[0],
        "width": size[1],
        "kind": kind if kind in ("vehicle", "pedestrian", "cyclist") else "other",
        "id": int(o.get("id", i)) if isinstance(o.get("id", i), (int, float)) else i,
    }


def _bad(v: Any, path: str, where: str) -> bool:
    raise MapError(f"{where}: expected booleans or 0/1, got {v!r}", path, where)


def _heading_rad(heading: np.ndarray, valid: np.ndarray, unit: str) -> np.ndarray:
    if unit not in ("auto", "rad", "deg"):
        raise ValueError(f"heading_unit: expected 'auto', 'rad' or 'deg', got {unit!r}")
    if unit == "auto":
        unit = "deg" if valid.any() and np.abs(heading[valid]).max() > 2 * np.pi + 0.5 else "rad"
    return np.deg2rad(heading) if unit == "deg" else heading


def _distinct(pts: np.ndarray) -> np.ndarray:
    keep = np.ones(len(pts), dtype=bool)
    keep[1:] = np.any(np.abs(np.diff(pts, axis=0)) > 1e-6, axis=1)
    return pts[keep]


def _roads(roads: Any, path: str, lane_width: float, speed_limit: float, connect_tol: float):
    lanes: list[LaneElement] = []
    edges: list[PolylineElement] = []
    walks: list[CrosswalkElement] = []
    skipped = {"short_lane": 0, "short_edge": 0, "short_crosswalk": 0, "unused_type": 0}
    for r, road in enumerate(_series(roads, None, path, "roads")):
        w = f"roads[{r}]"
        kind = _get(road, "type", path, w)
        if kind not in ("lane", "road_edge", "crosswalk"):
            skipped["unused_type"] += 1
            continue
        pts = _distinct(_points(_get(road, "geometry", path, w), path, f"{w}.geometry"))
        rid = f"{w}(id={road.get('id', r)})"
        if kind == "lane":
            if len(pts) < 2:
                skipped["short_lane"] += 1
                continue
            mph = road.get("speed_limit_mph")
            v = float(mph) * MPH if isinstance(mph, (int, float)) and mph > 0 else speed_limit
            lanes.append(LaneElement(centerline=pts, width=lane_width, speed_limit=v, source_id=rid))
        elif kind == "road_edge":
            if len(pts) < 2:
                skipped["short_edge"] += 1
                continue
            edges.append(PolylineElement(points=pts, kind=EdgeKind.ROAD_BORDER, source_id=rid))
        else:
            if len(pts) > 3 and np.allclose(pts[0], pts[-1]):
                pts = pts[:-1]  # closed ring: compile_map closes it itself
            if len(pts) < 3:
                skipped["short_crosswalk"] += 1
                continue
            walks.append(CrosswalkElement(polygon=pts, source_id=rid))
    _connect(lanes, connect_tol)
    return lanes, edges, walks, skipped


def _connect(lanes: list[LaneElement], tol: float) -> None:
    """Successors: lanes starting within `tol` [m] of a lane's end, turning less than 60 deg."""
    if not lanes:
        return
    starts = np.array([ln.centerline[0] for ln in lanes])
    d0 = np.array([ln.centerline[1] - ln.centerline[0] for ln in lanes])
    d0 /= np.linalg.norm(d0, axis=1, keepdims=True)
    for i, ln in enumerate(lanes):
        end, d1 = ln.centerline[-1], ln.centerline[-1] - ln.centerline[-2]
        d1 = d1 / np.linalg.norm(d1)
        near = np.flatnonzero((np.linalg.norm(starts - end, axis=1) <= tol) & (d0 @ d1 > 0.5))
        ln.successors = [int(j) for j in near if j != i]


def load_gpudrive_json(
    path: str | Path,
    lane_width: float = 4.0,
    speed_limit: float = 15.0,
    connect_tol: float = 1.0,
    heading_unit: str = "auto",
) -> LoggedScenario:
    """Read one scenario file (layout in the module docstring).

    Args:
        path: The JSON file.
        lane_width: Width given to every lane [m] (the layout has none).
        speed_limit: Lane speed limit [m/s] where a lane has no ``speed_limit_mph``.
        connect_tol: Largest gap [m] between a lane's end and a successor's start.
        heading_unit: "auto", "rad" or "deg".

    Raises:
        MapError: Unreadable JSON, a missing or malformed field (named with its index), tracks of
            unequal length, or no usable lane.
    """
    path = Path(path)
    src = str(path)
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError) as exc:
        raise MapError(f"cannot read the file: {exc}", src) from exc
    except json.JSONDecodeError as exc:
        raise MapError(f"not valid JSON: {exc}", src) from exc
    if not isinstance(data, dict):
        raise MapError(f"expected a JSON object with 'objects' and 'roads', got {type(data).__name__}", src)
    objs = _series(_get(data, "objects", src, ""), None, src, "objects")
    if not objs:
        raise MapError("'objects' is empty: a logged scenario needs at least one object", src, "objects")
    first = _object(objs[0], 0, None, src)
    parsed = [first] + [_object(o, i, len(first["xy"]), src) for i, o in enumerate(objs[1:], start=1)]
    lanes, edges, walks, skipped = _roads(
        _get(data, "roads", src, ""), src, lane_width, speed_limit, connect_tol
    )
    if not lanes:
        raise MapError(
            "no lane in 'roads' with at least 2 distinct points: nothing to drive on", src, "roads"
        )
    name = str(data.get("name") or data.get("scenario_id") or path.stem)
    road_map = compile_map(
        MapElements(name=name, source=src, lanes=lanes, road_edges=edges, crosswalks=walks)
    )
    shift = np.asarray(road_map.origin, dtype=np.float64)
    valid = np.stack([p["valid"] for p in parsed])
    xy = np.where(valid[..., None], np.stack([p["xy"] for p in parsed]) - shift, 0.0)
    heading = np.stack([_heading_rad(p["heading"], p["valid"], heading_unit) for p in parsed])
    meta = data.get("metadata") if isinstance(data.get("metadata"), dict) else {}
    sdc = meta.get("sdc_track_index", -1)
    return LoggedScenario(
        name=name,
        path=src,
        road_map=road_map,
        shift=shift,
        xy=xy,
        heading=np.arctan2(np.sin(heading), np.cos(heading)),
        vel=np.where(valid[..., None], np.stack([p["vel"] for p in parsed]), 0.0),
        valid=valid,
        length=np.array([p["length"] for p in parsed]),
        width=np.array([p["width"] for p in parsed]),
        kind=np.array([p["kind"] for p in parsed]),
        object_id=np.array([p["id"] for p in parsed], dtype=np.int64),
        sdc=int(sdc) if isinstance(sdc, int) and 0 <= sdc < len(parsed) else -1,
        edges=[e.points - shift for e in edges],
        skipped=skipped,
    )
