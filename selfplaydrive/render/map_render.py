"""Top-down matplotlib drawing of a `RoadMap` (section 2.1): for people checking a map.

`draw_map(ax, road_map)` draws onto any Axes, so the simulator renderer can draw vehicles on
top; `render_map(road_map, "out.png")` writes a PNG through the Agg canvas without touching
pyplot's global state (works headless and inside other GUIs).

What is drawn (local map frame, metres, equal aspect):

- lane areas (centerline buffered by half the lane width) in light grey, centerlines thin and
  coloured by `LaneKind` (junction lanes lighter);
- road edges black (outline edges, derived from the lane union, dashed);
- traffic-light stop lines thick, coloured by signal group;
- stop lines red with white dashes, yield lines white with red dashes;
- crosswalks as white hatched polygons;
- with ``arrows=True``: direction-of-travel arrows on every lane, red crosses at lanes without a
  successor (dead ends) and magenta links where a successor starts more than
  `LINK_GAP` [m] from the end of its predecessor (a lane-graph defect worth a look).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from selfplaydrive.maps.elements import EdgeKind, LaneKind, StopKind
from selfplaydrive.maps.roadmap import Polylines, RoadMap

__all__ = ["LANE_COLORS", "LINK_GAP", "draw_map", "lane_polygons", "render_map"]

LANE_COLORS = {LaneKind.VEHICLE: "#3b6fb6", LaneKind.BUS: "#d9861c", LaneKind.BICYCLE: "#2e9a46"}
ASPHALT = "#d4d4d4"
EDGE_COLOR = "black"
STOP_RED = "#d62020"
LINK_GAP = 0.5  # [m] successor links longer than this are drawn (gaps in the lane graph)
_LIGHT_CMAP = "tab10"

Region = Sequence[float]


def _check_region(region: Region | None) -> tuple[float, float, float, float] | None:
    if region is None:
        return None
    vals = tuple(float(v) for v in region)
    if len(vals) != 4 or not all(np.isfinite(vals)) or vals[0] >= vals[2] or vals[1] >= vals[3]:
        raise ValueError(
            f"region must be finite (xmin, ymin, xmax, ymax) with xmin < xmax and ymin < ymax, got {region}"
        )
    return vals  # type: ignore[return-value]


def _view(road_map: RoadMap, region: tuple[float, float, float, float] | None) -> np.ndarray:
    return np.asarray(region if region is not None else road_map.bounds, dtype=np.float64)


def _pieces(lines: Polylines, keep: np.ndarray | None = None) -> list[np.ndarray]:
    idx = range(len(lines)) if keep is None else np.flatnonzero(keep)
    return [lines[i] for i in idx]


def _bbox_hits(lines: Polylines, view: np.ndarray, pad: float = 0.0) -> np.ndarray:
    """(count,) bool: polyline bounding box overlaps the view rectangle (grown by `pad` [m])."""
    if len(lines) == 0:
        return np.zeros(0, dtype=bool)
    starts = lines.offsets[:-1]
    lo = np.minimum.reduceat(lines.points, starts, axis=0)
    hi = np.maximum.reduceat(lines.points, starts, axis=0)
    return (
        (hi[:, 0] >= view[0] - pad)
        & (lo[:, 0] <= view[2] + pad)
        & (hi[:, 1] >= view[1] - pad)
        & (lo[:, 1] <= view[3] + pad)
    )


def lane_polygons(road_map: RoadMap, lanes: Sequence[int] | np.ndarray | None = None) -> list[np.ndarray]:
    """Lane areas: each centerline offset by +-width/2 along its vertex normals.

    Args:
        road_map: The map.
        lanes: Lane indices (default all).

    Returns:
        One (2n, 2) float64 polygon [m] per lane (left side forward, right side back).
    """
    cl = road_map.lanes.centerlines
    idx = range(len(cl)) if lanes is None else lanes
    out = []
    for i in idx:
        p = cl[i].astype(np.float64)
        d = np.diff(p, axis=0)
        d /= np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)[:, None]
        # vertex tangent: mean of the adjacent segment directions (ends use their one segment)
        t = np.concatenate([d[:1], d[:-1] + d[1:], d[-1:]])
        t /= np.maximum(np.hypot(t[:, 0], t[:, 1]), 1e-9)[:, None]
        # miter: at a bend of angle a the offset along the bisector is (w/2) / cos(a/2); capped
        # at 2x so hairpins do not spike
        cos_half = np.ones(len(p))
        cos_half[1:-1] = np.sum(t[1:-1] * d[:-1], axis=1)
        half = 0.5 * float(road_map.lanes.width[i]) / np.maximum(cos_half, 0.5)
        n = np.stack([-t[:, 1], t[:, 0]], axis=1) * half[:, None]
        out.append(np.concatenate([p + n, (p - n)[::-1]]))
    return out


def _widths(ax: Axes, view: np.ndarray) -> dict[str, float]:
    """Line widths [pt] that follow the zoom: thin over a whole city, bold over a junction.

    Each is a physical width [m] times points per metre, clipped to a readable range.
    """
    box = ax.get_position()
    fig_w, fig_h = ax.figure.get_size_inches()
    ppm = 72.0 * min(box.width * fig_w / (view[2] - view[0]), box.height * fig_h / (view[3] - view[1]))
    spec = {
        "center": (0.25, 0.3, 0.8),
        "edge": (0.3, 0.4, 1.0),
        "light": (1.0, 1.6, 3.5),
        "stop": (0.8, 1.2, 3.0),
        "outline": (0.08, 0.2, 0.5),
    }
    return {k: float(np.clip(m * ppm, lo, hi)) for k, (m, lo, hi) in spec.items()}


def _draw_lanes(ax: Axes, m: RoadMap, hit: np.ndarray, fill: bool, lw: dict[str, float]) -> list[object]:
    handles: list[object] = []
    if fill and hit.any():
        ax.add_collection(
            PolyCollection(
                lane_polygons(m, np.flatnonzero(hit)), facecolors=ASPHALT, edgecolors="none", zorder=1
            )
        )
        handles.append(Patch(facecolor=ASPHALT, label="lane area"))
    for kind, color in LANE_COLORS.items():
        for junction in (False, True):
            sel = hit & (m.lanes.kind == kind) & (m.lanes.in_junction == junction)
            if not sel.any():
                continue
            ax.add_collection(
                LineCollection(
                    _pieces(m.lanes.centerlines, sel),
                    colors=color,
                    linewidths=lw["center"] * (0.7 if junction else 1.0),
                    alpha=0.45 if junction else 0.9,
                    zorder=3,
                )
            )
            if not junction:
                handles.append(Line2D([], [], color=color, lw=1, label=f"{kind.name.lower()} lane"))
    return handles


def _draw_edges(ax: Axes, m: RoadMap, view: np.ndarray, lw: dict[str, float]) -> list[object]:
    hit = _bbox_hits(m.road_edges, view)
    outline = m.edge_kind == EdgeKind.OUTLINE
    for sel, style in ((hit & ~outline, "solid"), (hit & outline, (0, (4, 2)))):
        if sel.any():
            ax.add_collection(
                LineCollection(
                    _pieces(m.road_edges, sel),
                    colors=EDGE_COLOR,
                    linewidths=lw["edge"],
                    linestyles=style,
                    zorder=4,
                )
            )
    return [Line2D([], [], color=EDGE_COLOR, lw=1, label="road edge")] if hit.any() else []


def _draw_lights(ax: Axes, m: RoadMap, view: np.ndarray, lw: dict[str, float]) -> list[object]:
    hit = _bbox_hits(m.light_lines, view)
    if not hit.any():
        return []
    import matplotlib

    cmap = matplotlib.colormaps[_LIGHT_CMAP]
    colors = [cmap(int(g) % cmap.N) for g in m.light_group[hit]]
    ax.add_collection(
        LineCollection(
            _pieces(m.light_lines, hit), colors=colors, linewidths=lw["light"], capstyle="butt", zorder=6
        )
    )
    return [Line2D([], [], color=cmap(0), lw=3, label="traffic-light line (colour: signal group)")]


def _draw_stops(ax: Axes, m: RoadMap, view: np.ndarray, lw: dict[str, float]) -> list[object]:
    hit = _bbox_hits(m.stop_lines, view)
    handles: list[object] = []
    for kind, base, dash, label in (
        (StopKind.STOP, STOP_RED, "white", "stop line"),
        (StopKind.YIELD, "white", STOP_RED, "yield line"),
    ):
        sel = hit & (m.stop_kind == kind)
        if not sel.any():
            continue
        pieces = _pieces(m.stop_lines, sel)
        # stop lines mostly red, yield lines mostly white: short dashes of the other colour
        ax.add_collection(
            LineCollection(pieces, colors=base, linewidths=lw["stop"], capstyle="butt", zorder=6)
        )
        ax.add_collection(
            LineCollection(
                pieces,
                colors=dash,
                linewidths=lw["stop"],
                linestyles=(0, (1, 2)),
                capstyle="butt",
                zorder=6.1,
            )
        )
        handles.append(Line2D([], [], color=dash, lw=2.5, ls=(0, (1, 2)), gapcolor=base, label=label))
    return handles


def _draw_crosswalks(ax: Axes, m: RoadMap, view: np.ndarray, lw: dict[str, float]) -> list[object]:
    hit = _bbox_hits(m.crosswalks, view)
    if not hit.any():
        return []
    ax.add_collection(
        PolyCollection(
            _pieces(m.crosswalks, hit),
            facecolors="white",
            edgecolors="#444444",
            linewidths=lw["outline"],
            hatch="////",
            zorder=5,
        )
    )
    return [Patch(facecolor="white", edgecolor="#444444", hatch="////", label="crosswalk")]


def _lane_points_at(m: RoadMap, lanes: np.ndarray, frac: float) -> tuple[np.ndarray, np.ndarray]:
    """Point and unit direction at fraction `frac` of the arc length of each lane."""
    pos = np.zeros((len(lanes), 2))
    tan = np.zeros((len(lanes), 2))
    for k, i in enumerate(lanes):
        p = m.lanes.centerlines[i].astype(np.float64)
        d = np.diff(p, axis=0)
        seg = np.hypot(d[:, 0], d[:, 1])
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        s = frac * cum[-1]
        j = min(int(np.searchsorted(cum, s, side="right")) - 1, len(seg) - 1)
        u = (s - cum[j]) / max(seg[j], 1e-9)
        pos[k] = p[j] + u * d[j]
        tan[k] = d[j] / max(seg[j], 1e-9)
    return pos, tan


def _draw_graph(ax: Axes, m: RoadMap, hit: np.ndarray, view: np.ndarray) -> list[object]:
    lanes = np.flatnonzero(hit)
    if len(lanes) == 0:
        return []
    span = max(view[2] - view[0], view[3] - view[1])
    arrow = float(np.clip(span / 120.0, 1.5, 12.0))  # [m] readable at any zoom
    pos, tan = _lane_points_at(m, lanes, 0.5)
    colors = [LANE_COLORS[LaneKind(int(k))] for k in m.lanes.kind[lanes]]
    ax.quiver(
        pos[:, 0] - 0.5 * arrow * tan[:, 0],
        pos[:, 1] - 0.5 * arrow * tan[:, 1],
        tan[:, 0] * arrow,
        tan[:, 1] * arrow,
        color=colors,
        angles="xy",
        scale_units="xy",
        scale=1.0,
        width=0.0022,
        headwidth=4.0,
        headlength=4.5,
        zorder=7,
    )
    handles: list[object] = [Line2D([], [], color="#3b6fb6", marker=">", lw=0, label="direction of travel")]
    cl = m.lanes.centerlines
    ends = np.array([cl[i][-1] for i in lanes], dtype=np.float64)
    dead = np.array([len(m.lanes.successors(i)) == 0 for i in lanes], dtype=bool)
    if dead.any():
        ax.plot(ends[dead, 0], ends[dead, 1], "x", color="red", ms=4, mew=1.0, zorder=8)
        handles.append(Line2D([], [], color="red", marker="x", lw=0, label="lane without successor"))
    links = [
        (cl[i][-1], cl[j][0])
        for i in lanes
        for j in m.lanes.successors(i)
        if np.hypot(*(cl[j][0] - cl[i][-1])) > LINK_GAP
    ]
    if links:
        ax.add_collection(LineCollection(links, colors="magenta", linewidths=1.0, zorder=8))
        handles.append(Line2D([], [], color="magenta", lw=1, label=f"successor link with gap > {LINK_GAP} m"))
    return handles


def draw_map(
    ax: Axes,
    road_map: RoadMap,
    *,
    arrows: bool = False,
    region: Region | None = None,
    fill_lanes: bool = True,
    legend: bool = True,
    lights: bool = True,
) -> Axes:
    """Draw `road_map` top-down onto `ax` (local frame, metres, equal aspect).

    Args:
        ax: Matplotlib axes; vehicles and other overlays can be drawn on it afterwards
            (map artists use zorder 1-8).
        road_map: The map.
        arrows: Draw direction-of-travel arrows, dead ends and gapped successor links.
        region: (xmin, ymin, xmax, ymax) [m] crop in the local frame; default the map bounds.
        fill_lanes: Fill lane areas (centerline +- width/2) in grey.
        legend: Add a legend of what was drawn (outside the axes, to the right).
        lights: Draw traffic-light stop lines (coloured by signal group); the episode renderer
            turns this off and draws them itself, coloured by their current state.

    Returns:
        `ax`.

    Raises:
        ValueError: If `region` is not a finite (xmin, ymin, xmax, ymax) with positive size.
    """
    view = _view(road_map, _check_region(region))
    margin = 0.0 if region is not None else 0.02 * max(view[2] - view[0], view[3] - view[1])
    ax.set_xlim(view[0] - margin, view[2] + margin)
    ax.set_ylim(view[1] - margin, view[3] + margin)
    ax.set_aspect("equal", adjustable="box")
    lw = _widths(ax, view + np.array([-margin, -margin, margin, margin]))
    lane_hit = _bbox_hits(road_map.lanes.centerlines, view, pad=float(road_map.lanes.width.max(initial=0.0)))
    handles = _draw_lanes(ax, road_map, lane_hit, fill_lanes, lw)
    handles += _draw_edges(ax, road_map, view, lw)
    handles += _draw_crosswalks(ax, road_map, view, lw)
    handles += _draw_stops(ax, road_map, view, lw)
    if lights:
        handles += _draw_lights(ax, road_map, view, lw)
    if arrows:
        handles += _draw_graph(ax, road_map, lane_hit, view)
    ax.set_xlabel("x [m] (local frame)")
    ax.set_ylabel("y [m] (local frame)")
    if legend and handles:
        ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    return ax


def render_map(
    road_map: RoadMap,
    path: str | os.PathLike[str],
    *,
    arrows: bool = False,
    region: Region | None = None,
    dpi: int = 150,
    size: float = 10.0,
    title: str | None = None,
) -> Path:
    """Render `road_map` to an image file (format from the suffix, e.g. .png) with Agg.

    Args:
        road_map: The map.
        path: Output file; parent folders are created.
        arrows: See `draw_map`.
        region: (xmin, ymin, xmax, ymax) [m] crop in the local frame.
        dpi: Dots per inch (pixels = size * dpi along the longer side).
        size: Length of the longer side of the map area [in].
        title: Figure title; default name, lane km and origin.

    Returns:
        The path written.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    if not (isinstance(dpi, int | np.integer) and 10 <= dpi <= 2000):
        raise ValueError(f"dpi must be an integer in [10, 2000], got {dpi!r}")
    view = _view(road_map, _check_region(region))
    w, h = view[2] - view[0], view[3] - view[1]
    scale = size / max(w, h)
    fig = Figure(figsize=(max(w * scale, 3.0) + 2.8, max(h * scale, 3.0) + 0.8), dpi=dpi)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    draw_map(ax, road_map, arrows=arrows, region=region)
    if title is None:
        title = (
            f"{road_map.name}: {road_map.vehicle_lane_km():.2f} lane-km, {len(road_map.lanes)} lanes; "
            f"origin ({road_map.origin[0]:.0f}, {road_map.origin[1]:.0f}) {road_map.crs}"
        )
    ax.set_title(title, fontsize=9)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi, bbox_inches="tight")
    return path
