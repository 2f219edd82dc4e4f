"""Concatenate the road data of several `RoadMap`s into the flat arrays the kernels read.

One env may mix maps (spec item 1): segments of map m occupy a contiguous index range, each map
keeps its own grid, and `cell_items` hold global segment indices, so a kernel only needs the
world's map index to query the right grid. The arrays are read-only and shared by all worlds.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from selfplaydrive.maps.roadmap import RoadMap, SegmentType


def _segment_groups(road_map: RoadMap) -> np.ndarray:
    """(N,) int32 signal group of each traffic-light segment, -1 for other segments."""
    seg = road_map.segments
    group = np.full(len(seg), -1, dtype=np.int32)
    is_light = seg.type == int(SegmentType.TRAFFIC_LIGHT)
    if is_light.any():
        group[is_light] = road_map.light_group[seg.owner[is_light]]
    return group


def build_atlas(maps: Sequence[RoadMap]) -> dict[str, np.ndarray]:
    """Flat arrays named as the `Atlas` struct fields of _sim/common.pxd.

    Args:
        maps: The env's maps; a world's `map_id` indexes this sequence.

    Returns:
        Dict of C-contiguous arrays (segments (Ns, ...), per-map grid data (M, ...)).
    """
    if not maps:
        raise ValueError("maps: expected at least one RoadMap, got an empty sequence")
    seg_base, cell_base, item_base = 0, 0, 0
    parts: dict[str, list[np.ndarray]] = {
        k: [] for k in ("start", "end", "mid", "dir", "len", "type", "group", "offsets", "items")
    }
    origin, cell, nx, ny, bases, max_len = [], [], [], [], [], []
    for m in maps:
        s, g = m.segments, m.grid
        parts["start"].append(s.start)
        parts["end"].append(s.end)
        parts["mid"].append(s.mid)
        parts["dir"].append(s.dir)
        parts["len"].append(s.length)
        parts["type"].append(s.type)
        parts["group"].append(_segment_groups(m))
        parts["offsets"].append(g.cell_offsets.astype(np.int64) + item_base)
        parts["items"].append(g.cell_items.astype(np.int64) + seg_base)
        origin.append(g.origin)
        cell.append(g.cell_size)
        nx.append(g.shape[0])
        ny.append(g.shape[1])
        bases.append(cell_base)
        max_len.append(float(s.length.max()) if len(s) else 0.0)
        seg_base += len(s)
        item_base += len(g.cell_items)
        cell_base += len(g.cell_offsets)
    if seg_base >= 2**31:
        raise ValueError(f"maps: {seg_base} segments in total, the simulator supports < 2**31")
    f4 = np.float32
    return {
        "seg_start": np.ascontiguousarray(np.concatenate(parts["start"]), dtype=f4),
        "seg_end": np.ascontiguousarray(np.concatenate(parts["end"]), dtype=f4),
        "seg_mid": np.ascontiguousarray(np.concatenate(parts["mid"]), dtype=f4),
        "seg_dir": np.ascontiguousarray(np.concatenate(parts["dir"]), dtype=f4),
        "seg_len": np.ascontiguousarray(np.concatenate(parts["len"]), dtype=f4),
        "seg_type": np.ascontiguousarray(np.concatenate(parts["type"]), dtype=np.int8),
        "seg_group": np.ascontiguousarray(np.concatenate(parts["group"]), dtype=np.int32),
        "grid_origin": np.ascontiguousarray(np.stack(origin), dtype=f4),
        "grid_cell": np.asarray(cell, dtype=f4),
        "grid_nx": np.asarray(nx, dtype=np.int32),
        "grid_ny": np.asarray(ny, dtype=np.int32),
        "cell_base": np.asarray(bases, dtype=np.int64),
        "cell_offsets": np.concatenate(parts["offsets"]).astype(np.int32),
        "cell_items": np.concatenate(parts["items"]).astype(np.int32),
        "max_seg_len": np.asarray(max_len, dtype=f4),
    }
