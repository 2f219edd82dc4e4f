"""Small synthetic maps for tests and benchmarks of the spawner (not a map generator for users).

`grid_elements` builds a rectangular grid of straight two-way roads (right-hand traffic) with
junction connector lanes, road edges, optional traffic lights, crosswalks, two lanes per
direction and stub roads that end at the map border (dead ends, like a real map's cut edge).
"""

from __future__ import annotations

import numpy as np

from selfplaydrive.maps.elements import (
    CrosswalkElement,
    LaneElement,
    MapElements,
    PolylineElement,
    TrafficLightElement,
)

_DIRS = ((1, 0), (0, 1), (-1, 0), (0, -1))  # E, N, W, S as grid steps


def _bezier(p0: np.ndarray, c: np.ndarray, p1: np.ndarray, n: int = 8) -> np.ndarray:
    t = np.linspace(0.0, 1.0, n)[:, None]
    return (1 - t) ** 2 * p0 + 2 * (1 - t) * t * c + t**2 * p1


def _line_intersection(p: np.ndarray, d: np.ndarray, q: np.ndarray, e: np.ndarray) -> np.ndarray:
    cross = d[0] * e[1] - d[1] * e[0]
    if abs(cross) < 1e-9:  # straight through: control point halfway
        return (p + q) / 2
    t = ((q - p)[0] * e[1] - (q - p)[1] * e[0]) / cross
    return p + t * d


def grid_elements(
    nx: int = 3,
    ny: int = 3,
    block: float = 100.0,
    lane_width: float = 3.5,
    speed_limit: float = 13.9,
    lanes_per_dir: int = 1,
    junction_radius: float = 12.0,
    lights: bool = True,
    crosswalks: bool = True,
    stubs: bool = True,
    name: str = "grid",
) -> MapElements:
    """A grid of nx x ny junctions `block` m apart joined by straight two-way roads.

    Args:
        nx, ny: Junctions along x and y (>= 1 each; roads need nx * ny >= 2 or stubs).
        block: Junction spacing [m].
        lane_width: [m].
        speed_limit: [m/s] of every lane.
        lanes_per_dir: Lanes per direction (2 gives legal lane changes).
        junction_radius: Roads stop this far from a junction centre [m].
        lights: Traffic lights on the approaches of junctions with 4 roads (2 groups each).
        crosswalks: A crosswalk across each road next to its start junction.
        stubs: Roads leaving the outer junctions to the map border (dead ends and sources).
        name: Map name.
    """
    nodes = {(i, j): np.array([i * block, j * block]) for i in range(nx) for j in range(ny)}
    roads = []  # (a_node_xy, b_node_xy, a_is_junction, b_is_junction)
    for (i, j), p in nodes.items():
        for di, dj in ((1, 0), (0, 1)):
            if (i + di, j + dj) in nodes:
                roads.append((p, nodes[(i + di, j + dj)], True, True))
    if stubs:
        for (i, j), p in nodes.items():
            for di, dj in _DIRS:
                if (i + di, j + dj) not in nodes:
                    roads.append((p, p + 0.6 * block * np.array([di, dj]), True, False))
    lanes: list[LaneElement] = []
    edges: list[PolylineElement] = []
    walks: list[CrosswalkElement] = []
    arrive: dict[tuple[float, float], list[tuple[int, np.ndarray]]] = {}
    leave: dict[tuple[float, float], list[tuple[int, np.ndarray]]] = {}
    half = lanes_per_dir * lane_width
    for r, (a, b, a_j, b_j) in enumerate(roads):
        d = (b - a) / np.linalg.norm(b - a)
        right = np.array([d[1], -d[0]])
        pa = a + d * (junction_radius if a_j else 0.0)
        pb = b - d * (junction_radius if b_j else 0.0)
        for sign, (p_from, p_to, key_from, key_to) in ((1, (pa, pb, a, b)), (-1, (pb, pa, b, a))):
            ids = []
            for k in range(lanes_per_dir):
                off = sign * right * (k + 0.5) * lane_width
                cl = np.array([p_from + off, p_to + off])
                idx = len(lanes)
                lanes.append(
                    LaneElement(cl, lane_width, speed_limit, source_id=f"road{r}/{'fb'[sign < 0]}{k}")
                )
                ids.append(idx)
                arrive.setdefault(tuple(key_to), []).append((idx, -sign * d))
                leave.setdefault(tuple(key_from), []).append((idx, sign * d))
            for k, idx in enumerate(ids):  # k = 0 is the left (inner) lane
                if k + 1 < lanes_per_dir:
                    lanes[idx].right, lanes[idx].right_change_legal = ids[k + 1], True
                    lanes[ids[k + 1]].left, lanes[ids[k + 1]].left_change_legal = idx, True
        for sign in (1, -1):
            edges.append(PolylineElement(np.array([pa + sign * right * half, pb + sign * right * half])))
        if crosswalks and a_j:
            c = pa + d * 4.0
            w = np.array(
                [
                    c - right * half - d * 1.5,
                    c + right * half - d * 1.5,
                    c + right * half + d * 1.5,
                    c - right * half + d * 1.5,
                ]
            )
            walks.append(CrosswalkElement(w, source_id=f"cw{r}"))
    lights_out = _junctions(nodes, lanes, arrive, leave, lights)
    return MapElements(
        name=name,
        source=f"grid_elements({nx}, {ny})",
        lanes=lanes,
        road_edges=edges,
        traffic_lights=lights_out,
        crosswalks=walks,
    )


def _junctions(nodes, lanes, arrive, leave, lights: bool) -> list[TrafficLightElement]:
    """Connector lanes (no U-turns) from every arriving to every leaving lane of each junction."""
    out: list[TrafficLightElement] = []
    for n, centre in enumerate(nodes.values()):
        key_xy = tuple(centre)
        ins, outs = arrive.get(key_xy, []), leave.get(key_xy, [])
        for li, d_in in ins:
            # d_in points from the junction towards where the lane came from
            k_in = int(lanes[li].source_id[-1])
            for lo, d_out in outs:
                if np.allclose(d_in, d_out) or int(lanes[lo].source_id[-1]) != k_in:
                    continue
                p0, p1 = lanes[li].centerline[-1], lanes[lo].centerline[0]
                c = _line_intersection(p0, -d_in, p1, -d_out)
                idx = len(lanes)
                lanes.append(
                    LaneElement(
                        _bezier(p0, c, p1),
                        lanes[li].width,
                        lanes[li].speed_limit,
                        source_id=f"j{n}/{li}-{lo}",
                        successors=[lo],
                        in_junction=True,
                    )
                )
                lanes[li].successors.append(idx)
        if lights and len({tuple(np.round(d, 3)) for _, d in ins}) == 4:
            for li, d_in in ins:
                p = lanes[li].centerline[-1]
                right = np.array([-d_in[1], d_in[0]])
                w = lanes[li].width / 2
                group = 2 * n + int(abs(d_in[0]) > 0.5)
                out.append(TrafficLightElement(np.array([p - right * w, p + right * w]), group, [li]))
    # renumber groups densely
    used = sorted({t.signal_group for t in out})
    remap = {g: i for i, g in enumerate(used)}
    for t in out:
        t.signal_group = remap[t.signal_group]
    return out
