"""Packing of per-map tables into a map-bound term's float32 args (docs/components.md
"Map-bound terms"; the kernels in _sim/rules.pyx read this layout).

Layout of the args::

    [0] state offset (first `term_state` column of the term; 0 without state)
    [1] layout version (`TABLE_VERSION`)
    [2] number of maps M
    [3 : 3 + P] the term's P parameters
    [3 + P : 3 + P + M] offset of each map's body (index into the args)
    bodies

A map body is a uniform grid over records of fixed width (a zone, a line segment, a polygon, a
lane segment)::

    [0, 1] grid origin x, y [m]; [2] cell edge [m]; [3, 4] cells nx, ny (x-major: cell
    ix * ny + iy); [5] record width R; [6, 7, 8] offsets from the body start of the cell
    CSR (nx * ny + 1 entries), the items (record indices) and the records (n * R floats)

Cell c lists the records whose bounding box, grown by `REACH`, meets it, so the records a
move of at most `REACH` m ending in cell c can meet are all listed there. Integers are stored
as float32, exact below 2**24; `pack` raises when a table is larger.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from selfplaydrive.errors import ConfigError

TABLE_VERSION = 1
HEADER = 3
EXACT = 2**24  # float32 holds every integer below this exactly
REACH = 5.0  # [m] longest move per step the grids cover (50 m/s at dt 0.1 s)
CELL = 10.0  # [m] grid cell edge
MAX_CELLS = 1 << 20  # cells per map; the cell grows on larger maps


def grid_body(records: np.ndarray, boxes: np.ndarray, cell: float = CELL) -> np.ndarray:
    """One map's body: the records and the grid listing them.

    Args:
        records: (n, R) float records.
        boxes: (n, 4) bounding boxes xmin, ymin, xmax, ymax [m] of the records.
        cell: Grid cell edge [m] (grown until the grid has at most `MAX_CELLS` cells).

    Returns:
        (size,) float64 body (`pack` converts and checks it).
    """
    records = np.asarray(records, np.float64)
    n, width = records.shape
    if n == 0:
        return np.array([0.0, 0.0, cell, 1, 1, max(width, 1), 9, 11, 11, 0.0, 0.0])
    lo = np.asarray(boxes, np.float64)[:, :2] - REACH
    hi = np.asarray(boxes, np.float64)[:, 2:] + REACH
    origin = lo.min(axis=0)
    span = hi.max(axis=0) - origin
    while np.prod(np.floor(span / cell) + 1) > MAX_CELLS:
        cell *= 2.0
    nx, ny = (np.floor(span / cell) + 1).astype(np.int64)
    i0 = np.floor((lo - origin) / cell).astype(np.int64)
    i1 = np.minimum(np.floor((hi - origin) / cell).astype(np.int64), [nx - 1, ny - 1])
    cells, items = _cover(i0, i1, int(ny))
    order = np.argsort(cells, kind="stable")
    offsets = np.zeros(nx * ny + 1, np.int64)
    np.cumsum(np.bincount(cells, minlength=nx * ny), out=offsets[1:])
    head = 9
    return np.concatenate(
        [
            [
                origin[0],
                origin[1],
                cell,
                nx,
                ny,
                width,
                head,
                head + len(offsets),
                head + len(offsets) + len(items),
            ],
            offsets,
            items[order],
            records.reshape(-1),
        ]
    )


def _cover(i0: np.ndarray, i1: np.ndarray, ny: int) -> tuple[np.ndarray, np.ndarray]:
    """(cell, record) pairs of every cell in each record's index box [i0, i1]."""
    cells, items = [], []
    nxs, nys = i1[:, 0] - i0[:, 0] + 1, i1[:, 1] - i0[:, 1] + 1
    for dx in range(int(nxs.max())):
        for dy in range(int(nys.max())):
            k = np.flatnonzero((dx < nxs) & (dy < nys))
            cells.append((i0[k, 0] + dx) * ny + i0[k, 1] + dy)
            items.append(k)
    return np.concatenate(cells), np.concatenate(items)


def pack(name: str, params: Sequence[float], bodies: Sequence[np.ndarray]) -> np.ndarray:
    """The args of a map-bound term: header, parameters, body offsets, bodies.

    Raises:
        ConfigError: A table too large for exact float32 indices (2**24), or non-finite data.
    """
    start = HEADER + len(params) + len(bodies)
    offsets = start + np.concatenate([[0], np.cumsum([len(b) for b in bodies])[:-1]]).astype(np.int64)
    total = start + sum(len(b) for b in bodies)
    if total >= EXACT:
        raise ConfigError(
            f"reward term {name!r}: its map tables need {total} floats; indices stored as float32 are "
            f"exact only below 2**24 = {EXACT}: use fewer or smaller maps with this term"
        )
    out = np.concatenate([[0.0, TABLE_VERSION, len(bodies)], list(params), offsets, *bodies]).astype(
        np.float32
    )
    if not np.isfinite(out).all():
        raise ConfigError(f"reward term {name!r}: its map tables hold non-finite numbers")
    return out
