"""Plain NumPy reference of the traffic-rule encoder (_sim/obs_rules.pyx; issue #15 item 1;
docs/observation.md "Traffic-rule features"), for tests: the paper's rows of an env, then the
rule features, found from the `RoadMap`s themselves (segment type, owner and `stop_kind`, the
crosswalk outlines) rather than from the packed data the kernel reads, in explicit loops.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from selfplaydrive.maps.roadmap import RoadMap, SegmentType, StopKind
from selfplaydrive.obs import rule_features as rf
from selfplaydrive.obs.layout import EGO_FEATURES, OBJECT_FEATURES, ROAD_FEATURES

TYPE_COL = ROAD_FEATURES.index("type")
STATE_COL = ROAD_FEATURES.index("light_state")


def occupied_crosswalks(road_map: RoadMap, state: Any, w: int) -> np.ndarray:
    """(crosswalks of the map,) bool: which crosswalks of world w's map are occupied."""
    P = state.ped_valid.shape[0] // state.map_id.shape[0]
    k = slice(w * P, (w + 1) * P)
    here = state.ped_valid[k].astype(bool) & state.ped_here[k].astype(bool)
    x, y = state.ped_x[k][here], state.ped_y[k][here]
    vx, vy = state.ped_vx[k][here], state.ped_vy[k][here]
    out = np.zeros(len(road_map.crosswalks), dtype=bool)
    for c, poly in enumerate(rf.crosswalk_polygons(road_map)):
        out[c] = bool(rf.pedestrians_on_crosswalk(poly, x, y, vx, vy).any())
    return out


def encode(
    paper_rows: np.ndarray,
    state: Any,
    maps: Sequence[RoadMap],
    atlas: Mapping[str, np.ndarray],
    max_objects: int,
    max_road: int,
) -> np.ndarray:
    """The rule encoder's rows: `paper_rows` (N, obs_dim) of the paper encoder with the rule
    features written into the road rows of every active slot.

    Args:
        paper_rows: The paper encoder's observations of the same state.
        state: The env's state (`VecEnv.state`: road_idx, road_n, active, map_id, pedestrians).
        maps: The env's maps; atlas: `build_atlas(maps)` (its `seg_id`).
        max_objects, max_road: The layout's sizes.
    """
    out = np.array(paper_rows, dtype=np.float32, copy=True)
    base = np.concatenate([[0], np.cumsum([len(m.segments) for m in maps])])
    seg_id = np.asarray(atlas["seg_id"])
    W = state.map_id.shape[0]
    A = state.active.shape[0] // W
    road0 = len(EGO_FEATURES) + max_objects * len(OBJECT_FEATURES)
    rd = len(ROAD_FEATURES)
    for w in range(W):
        m = int(state.map_id[w])
        road_map = maps[m]
        busy = occupied_crosswalks(road_map, state, w)
        for a in range(A):
            i = w * A + a
            if not state.active[i]:
                continue
            for k in range(int(state.road_n[i])):
                j = int(seg_id[state.road_idx[i, k]]) - int(base[m])  # segment of map m
                kind, owner = int(road_map.segments.type[j]), int(road_map.segments.owner[j])
                col = road0 + k * rd
                if kind == SegmentType.STOP_LINE and road_map.stop_kind[owner] == StopKind.STOP:
                    out[i, col + TYPE_COL] = np.float32(rf.STOP_LINE_TYPE)
                elif kind == SegmentType.CROSSWALK and busy[owner]:
                    out[i, col + STATE_COL] = np.float32(rf.CROSSWALK_OCCUPIED)
    return out
