"""Lane geometry tables of the rule-based driver: every lane of every map of an env, flattened
into one global lane numbering so that all lookups are vectorised NumPy over agents.

Map m's lanes get global ids `lane_base[m] + local id`; its points are shifted by
`m * MAP_SHIFT` along x inside the k-d tree only, so one tree serves all maps without two maps'
lanes ever being neighbours.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial import cKDTree

from selfplaydrive.maps.roadmap import RoadMap

MAP_SHIFT = 1.0e6  # [m] x offset between maps in the k-d tree (maps are < 100 km across)
SAMPLE_STEP = 2.0  # [m] spacing of the localisation samples along each centerline
CHORD_POINTS = 8  # resampled points per lane used to score successors against a waypoint


@dataclass(frozen=True)
class LaneTable:
    """Centerline geometry, lane graph and traffic-light stop positions of all maps.

    Attributes:
        points: (P, 2) float64 centerline points [m], all lanes of all maps (local frames).
        seg_len: (P,) float64 length of the segment from point k to k + 1 (0 at a lane's last
            point) [m].
        s_pt: (P,) float64 arc length of each point within its lane [m].
        key: (P,) float64 `lane_key[lane] + s_pt`, strictly ordered; lookups search it.
        offsets: (L + 1,) int64 CSR offsets of lanes into `points`.
        length: (L,) float64 lane length [m].
        lane_key: (L,) float64 key of each lane's first point.
        speed_limit: (L,) float64 [m/s].
        succ: (L, M) int64 successor lanes (global ids), -1 padded.
        chord: (L, CHORD_POINTS, 2) float64 evenly spaced points along each lane [m].
        light_s: (L, J) float64 arc length where the lane crosses a traffic-light line [m].
        light_group: (L, J) int64 signal group of that line (map-local), -1 padded.
        lane_map: (L,) int64 map of each lane.
        lane_base: (num_maps,) int64 first global lane id of each map.
        tree: k-d tree over the localisation samples.
        sample_lane: (Q,) int64 lane of each sample.
        sample_s: (Q,) float64 arc length of each sample [m].
    """

    points: np.ndarray
    seg_len: np.ndarray
    s_pt: np.ndarray
    key: np.ndarray
    offsets: np.ndarray
    length: np.ndarray
    lane_key: np.ndarray
    speed_limit: np.ndarray
    succ: np.ndarray
    chord: np.ndarray
    light_s: np.ndarray
    light_group: np.ndarray
    lane_map: np.ndarray
    lane_base: np.ndarray
    tree: cKDTree
    sample_lane: np.ndarray
    sample_s: np.ndarray

    @staticmethod
    def build(maps: Sequence[RoadMap]) -> LaneTable:
        """Flatten the lanes of `maps` (the env's map list, in order)."""
        parts = [_map_part(m) for m in maps]
        counts = [len(p["length"]) for p in parts]
        if sum(counts) == 0:
            raise ValueError("rule-based driver: the env's maps have no lanes to follow")
        lane_base = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
        pts_base = np.concatenate([[0], np.cumsum([len(p["points"]) for p in parts])[:-1]])
        cat = {k: np.concatenate([p[k] for p in parts]) for k in ("points", "length", "speed_limit")}
        offsets = np.concatenate(
            [[0]] + [p["offsets"][1:] + b for p, b in zip(parts, pts_base, strict=True)]
        ).astype(np.int64)
        succ = _pad_cat(
            [np.where(p["succ"] >= 0, p["succ"] + b, -1) for p, b in zip(parts, lane_base, strict=True)]
        )
        light_s = _pad_cat([p["light_s"] for p in parts], fill=np.inf)
        light_group = _pad_cat([p["light_group"] for p in parts])
        lane_map = np.repeat(np.arange(len(maps)), counts)
        pts = cat["points"]
        lane_of_pt = np.repeat(np.arange(len(cat["length"])), np.diff(offsets))
        d = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        last = np.zeros(len(pts), dtype=bool)
        last[offsets[1:] - 1] = True
        seg_len = np.where(last, 0.0, np.concatenate([d, [0.0]]))
        cum = np.concatenate([[0.0], np.cumsum(seg_len)])[:-1]
        s_pt = cum - cum[offsets[:-1]][lane_of_pt]
        lane_key = np.concatenate([[0.0], np.cumsum(cat["length"] + 1.0)[:-1]])
        table = LaneTable(
            points=pts,
            seg_len=seg_len,
            s_pt=s_pt,
            key=lane_key[lane_of_pt] + s_pt,
            offsets=offsets,
            length=cat["length"],
            lane_key=lane_key,
            speed_limit=cat["speed_limit"],
            succ=succ,
            chord=np.zeros((0, CHORD_POINTS, 2)),
            light_s=light_s,
            light_group=light_group,
            lane_map=lane_map,
            lane_base=lane_base,
            tree=None,
            sample_lane=np.zeros(0, np.int64),
            sample_s=np.zeros(0),
        )
        return table._with_samples()

    def _with_samples(self) -> LaneTable:
        """Add the chord points and the k-d tree of localisation samples (vectorised)."""
        L = len(self.length)
        u = np.linspace(0.0, 1.0, CHORD_POINTS)[None, :] * self.length[:, None]
        chord, _ = self.point_at(np.repeat(np.arange(L), CHORD_POINTS).reshape(L, -1), u)
        count = np.floor(self.length / SAMPLE_STEP).astype(np.int64) + 2  # every step, and the end
        lane = np.repeat(np.arange(L), count)
        first = np.concatenate([[0], np.cumsum(count)[:-1]])
        k = np.arange(len(lane)) - first[lane]
        s = np.minimum(k * SAMPLE_STEP, self.length[lane])
        xy, _ = self.point_at(lane, s)
        xy[:, 0] += self.lane_map[lane] * MAP_SHIFT
        return replace(self, chord=chord, tree=cKDTree(xy), sample_lane=lane, sample_s=s)

    def point_at(self, lane: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Point and unit tangent at arc length `s` [m] (clipped to the lane) of `lane`.

        Args:
            lane: (...) int global lane ids (>= 0).
            s: (...) float arc lengths [m].

        Returns:
            xy (..., 2) [m] and tangent (..., 2).
        """
        s = np.clip(s, 0.0, self.length[lane])
        k = np.searchsorted(self.key, self.lane_key[lane] + s, side="right") - 1
        k = np.clip(k, self.offsets[lane], np.maximum(self.offsets[lane + 1] - 2, self.offsets[lane]))
        p0 = self.points[k]
        p1 = self.points[np.minimum(k + 1, len(self.points) - 1)]
        seg = p1 - p0
        n = np.maximum(self.seg_len[k], 1e-9)
        t = np.clip((s - self.s_pt[k]) / n, 0.0, 1.0)
        return p0 + t[..., None] * seg, seg / n[..., None]


def _map_part(m: RoadMap) -> dict[str, np.ndarray]:
    lanes = m.lanes
    cl = lanes.centerlines
    L = len(lanes)
    pts = cl.points.astype(np.float64)
    length = cl.lengths()
    counts = np.diff(lanes.succ_offsets).astype(np.int64)
    M = max(1, int(counts.max()) if L else 1)
    succ_arr = np.full((L, M), -1, dtype=np.int64)
    row = np.repeat(np.arange(L), counts)
    col = np.arange(len(row)) - np.repeat(lanes.succ_offsets[:-1].astype(np.int64), counts)
    succ_arr[row, col] = lanes.succ_index
    light_s, light_group = _lights(m, length)
    return dict(
        points=pts,
        offsets=np.asarray(cl.offsets, dtype=np.int64),
        length=length,
        speed_limit=lanes.speed_limit.astype(np.float64),
        succ=succ_arr,
        light_s=light_s,
        light_group=light_group,
    )


def _lights(m: RoadMap, length: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Arc length along each controlled lane where its traffic-light line lies (section 2.2)."""
    from shapely import LineString, Point

    L = len(length)
    per_lane: list[list[tuple[float, int]]] = [[] for _ in range(L)]
    for i in range(len(m.light_lines)):
        line = LineString(m.light_lines[i].astype(np.float64))
        for lane in m.light_lane_index[m.light_lane_offsets[i] : m.light_lane_offsets[i + 1]]:
            cl = LineString(m.lanes.centerlines[int(lane)].astype(np.float64))
            hit = cl.intersection(line)
            # a line that stops short of the centerline still applies: project its nearest point
            p = (
                hit.representative_point()
                if not hit.is_empty
                else line.interpolate(line.project(cl.centroid))
            )
            per_lane[int(lane)].append((float(cl.project(Point(p))), int(m.light_group[i])))
    J = max([1] + [len(x) for x in per_lane])
    s = np.full((L, J), np.inf)
    g = np.full((L, J), -1, dtype=np.int64)
    for lane, items in enumerate(per_lane):
        for j, (sj, gj) in enumerate(items):
            s[lane, j], g[lane, j] = sj, gj
    return s, g


def _pad_cat(arrays: list[np.ndarray], fill: float = -1) -> np.ndarray:
    width = max(a.shape[1] for a in arrays)
    dtype = arrays[0].dtype
    out = [np.pad(a, ((0, 0), (0, width - a.shape[1])), constant_values=fill).astype(dtype) for a in arrays]
    return np.concatenate(out)
