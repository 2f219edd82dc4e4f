"""Concatenate the road data of several `RoadMap`s into the flat arrays the kernels read.

One env may mix maps (spec item 1): segments of map m occupy a contiguous range of atlas
positions, each map has its own grid, and `cell_offsets` hold global atlas positions, so a
kernel only needs the world's map index to query the right grid. The arrays are read-only and
shared by all worlds.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from selfplaydrive.maps.roadmap import RoadMap, SegmentType

# [m] cell edge of the road gather grid. Each grid column meeting the disc is one contiguous
# run of midpoints scanned with SIMD (_sim/scan.h), so fewer, longer runs win over scanning a
# few more candidates beyond the disc: 20 m cells take ~1.5 % fewer instructions per
# agent-step than 12 m (bundled town, Tartu, Town03) and ~8 % fewer than 6 m (bundled town;
# callgrind), and ran 5-8 % faster than 12 m in interleaved timings.
RING_CELL = 20.0


def _segment_groups(road_map: RoadMap) -> np.ndarray:
    """(N,) int32 signal group of each traffic-light segment, -1 for other segments."""
    seg = road_map.segments
    group = np.full(len(seg), -1, dtype=np.int32)
    is_light = seg.type == int(SegmentType.TRAFFIC_LIGHT)
    if is_light.any():
        group[is_light] = road_map.light_group[seg.owner[is_light]]
    return group


def _cell_order(mid: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray, int, int, np.ndarray]:
    """Bucket midpoints into a uniform grid that just covers them.

    Returns:
        order: (n,) segment indices sorted by cell (x-major, y contiguous), stable.
        origin: (2,) lower-left corner [m].
        nx, ny: cells along x and y.
        offsets: (nx * ny + 1,) CSR start of each cell in `order`.
    """
    if len(mid) == 0:
        return np.zeros(0, np.int64), np.zeros(2, np.float32), 1, 1, np.zeros(2, np.int64)
    lo = mid.min(axis=0).astype(np.float64) - 1e-3
    hi = mid.max(axis=0).astype(np.float64)
    nx = int(np.floor((hi[0] - lo[0]) / cell)) + 1
    ny = int(np.floor((hi[1] - lo[1]) / cell)) + 1
    origin = lo.astype(np.float32)
    ix = np.clip(np.floor((mid[:, 0] - origin[0]) / np.float32(cell)).astype(np.int64), 0, nx - 1)
    iy = np.clip(np.floor((mid[:, 1] - origin[1]) / np.float32(cell)).astype(np.int64), 0, ny - 1)
    key = ix * ny + iy
    order = np.argsort(key, kind="stable")
    offsets = np.zeros(nx * ny + 1, dtype=np.int64)
    np.cumsum(np.bincount(key, minlength=nx * ny), out=offsets[1:])
    return order, origin, nx, ny, offsets


def build_atlas(
    maps: Sequence[RoadMap], cell_size: float = RING_CELL, length_scale: float = 20.0
) -> dict[str, np.ndarray]:
    """Flat arrays named as the `Atlas` struct fields of _sim/common.pxd.

    Segments are stored in *atlas order*: map by map, and inside a map sorted by the cell of a
    uniform grid of `cell_size` [m] (x-major), so the road gather reads the midpoints of each
    grid column's cells as one contiguous run. `seg_id` maps an atlas position to the
    segment's global index (map m's segment j has global index j + number of segments of maps
    before m). Arrays the SIMD kernels read whole vectors of
    (`seg_mx`, `seg_my`, `seg_cols`, `seg_id`, `seg_group`) carry 8 entries of padding.

    Args:
        maps: The env's maps; a world's `map_id` indexes this sequence.
        cell_size: Grid cell edge [m] of the road gather.
        length_scale: Observation scale of segment lengths [m] (`SimParams.length_scale`).

    Returns:
        Dict of C-contiguous arrays (segments (Ns, ...), per-map grid data (M, ...)).
    """
    if not maps:
        raise ValueError("maps: expected at least one RoadMap, got an empty sequence")
    if not (np.isfinite(cell_size) and cell_size > 0):
        raise ValueError(f"cell_size: expected a positive number of metres, got {cell_size!r}")
    seg_base, cell_base = 0, 0
    parts: dict[str, list[np.ndarray]] = {
        k: [] for k in ("mid", "dir", "len", "type", "group", "offsets", "id")
    }
    origin, nx, ny, bases, max_len = [], [], [], [], []
    for m in maps:
        s = m.segments
        order, org, mx, my, offsets = _cell_order(np.asarray(s.mid, dtype=np.float32), cell_size)
        parts["mid"].append(s.mid[order])
        parts["dir"].append(s.dir[order])
        parts["len"].append(s.length[order])
        parts["type"].append(s.type[order])
        parts["group"].append(_segment_groups(m)[order])
        parts["id"].append(order + seg_base)
        parts["offsets"].append(offsets + seg_base)
        origin.append(org)
        nx.append(mx)
        ny.append(my)
        bases.append(cell_base)
        max_len.append(float(s.length.max()) if len(s) else 0.0)
        seg_base += len(s)
        cell_base += len(offsets)
    if seg_base >= 2**31:
        raise ValueError(f"maps: {seg_base} segments in total, the simulator supports < 2**31")
    f4 = np.float32
    mid = np.ascontiguousarray(np.concatenate(parts["mid"]), dtype=f4)
    seg_id = np.concatenate(parts["id"]).astype(np.int32)
    seg_dir = np.ascontiguousarray(np.concatenate(parts["dir"]), dtype=f4)
    seg_len = np.ascontiguousarray(np.concatenate(parts["len"]), dtype=f4)
    seg_type = np.ascontiguousarray(np.concatenate(parts["type"]), dtype=np.int8)
    seg_group = np.ascontiguousarray(np.concatenate(parts["group"]), dtype=np.int32)
    if len(seg_type) and not (seg_type.min() >= 0 and seg_type.max() < 8):
        bad = int(np.flatnonzero((seg_type < 0) | (seg_type >= 8))[0])
        raise ValueError(
            f"maps: segment at atlas position {bad} has type {int(seg_type[bad])}, expected a "
            "SegmentType in [0, 8)"
        )
    # one 32-byte record per segment, read by the road events and the observation rows
    # (_sim/road.pyx, _sim/rows.h): midpoint, direction, the row's scaled length and type,
    # the length [m] and the signal group (-1: none)
    rec = np.zeros((len(seg_id), 8), dtype=f4)
    rec[:, 0:2] = mid
    rec[:, 2:4] = seg_dir
    rec[:, 4] = np.minimum(seg_len / f4(length_scale), f4(1.0))
    rec[:, 5] = seg_type.astype(f4) * f4(0.25)
    rec[:, 6] = seg_len
    rec[:, 7] = seg_group.astype(f4)
    # the same features as columns (dir x, dir y, length, type), for blocks of rows whose
    # segments are consecutive atlas positions (_sim/rows.h, SSE2 version); 8 entries of padding, like
    # seg_mx, seg_my, seg_id and seg_group: the SIMD kernels read whole vectors
    pad = 8
    cols = np.zeros((4, len(seg_id) + pad), dtype=f4)
    cols[:, : len(seg_id)] = rec[:, 2:6].T
    return {
        # 8 floats of padding: the SIMD scan reads whole vectors past a run (_sim/scan.h)
        "seg_mx": np.concatenate([mid[:, 0], np.zeros(8, f4)]),
        "seg_my": np.concatenate([mid[:, 1], np.zeros(8, f4)]),
        "seg_rec": rec,
        "seg_cols": cols,
        "seg_group": np.concatenate([seg_group, np.full(pad, -1, np.int32)]),
        "seg_id": np.concatenate([seg_id, np.zeros(pad, np.int32)]),
        "grid_origin": np.ascontiguousarray(np.stack(origin), dtype=f4),
        "grid_cell": np.full(len(maps), cell_size, dtype=f4),
        "grid_nx": np.asarray(nx, dtype=np.int32),
        "grid_ny": np.asarray(ny, dtype=np.int32),
        "cell_base": np.asarray(bases, dtype=np.int64),
        "cell_offsets": np.concatenate(parts["offsets"]).astype(np.int32),
        "max_seg_len": np.asarray(max_len, dtype=f4),
    }
