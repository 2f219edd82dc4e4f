"""Top-down frames of a recorded episode (paper section 2: one world's 200 x 200 m region).

Each frame is the map (drawn once per camera extent by `draw_map` into a raster, `MapLayer`)
with the moving parts drawn on top by matplotlib's Agg renderer:

- traffic-light stop lines coloured by their signal group's state (section 2.2): off grey,
  red, yellow, green;
- controlled agents as oriented boxes (the true collision boxes, section 2.6) with a white
  triangle in the front half pointing along the heading; box colour by status: driving
  (blue), started parked at the roadside and driving (purple), ended (dark grey when it stays
  as an obstacle, a hollow outline where it was removed); a red outline marks a car with a
  collision, road-edge or red-light event in the last step, an amber one the followed car;
- static vehicles grey, pedestrians as small magenta squares;
- per agent (one colour each): its trajectory tail, its current waypoint (large star) and the
  remaining ones (small stars) joined by a thin dashed line from the car;
- the episode time and the event counts of the episode so far in the corners, a scale bar.

Speed: the map raster is cut (NumPy slicing, integer pixel offsets) straight into the Agg
canvas buffer, then only the dynamic artists are drawn (`Axes.draw_artist`), so a frame costs
no map drawing at all; the raster is made once per map and camera extent (per episode for the
fixed camera, per region plus margin for the follow camera).
"""

from __future__ import annotations

from collections import OrderedDict, deque
from collections.abc import Iterator, Sequence

import matplotlib
import matplotlib.font_manager
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection, PathCollection, PolyCollection
from matplotlib.colors import to_rgba, to_rgba_array
from matplotlib.figure import Figure
from matplotlib.markers import MarkerStyle
from matplotlib.transforms import IdentityTransform
from PIL import Image, ImageDraw, ImageFont

from selfplaydrive.maps.roadmap import RoadMap
from selfplaydrive.render.map_render import draw_map
from selfplaydrive.render.record import EVENT_NAMES, Recording, WorldFrame

__all__ = ["LIGHT_COLORS", "STATUS_COLORS", "EpisodeRenderer", "MapLayer", "box_corners"]

LIGHT_COLORS = {0: "#4d4d4d", 1: "#e41a1c", 2: "#ffc000", 3: "#1a9e3a"}  # off, red, yellow, green
STATUS_COLORS = {"active": "#2160c4", "parked": "#8e3fc4", "ended": "#4a4a4a"}
INCIDENT_COLOR = "#ff1010"  # outline of a car with a collision, road-edge or red-light event
INCIDENT_BITS = 1 | 2 | 4 | 8  # EV_COLLIDE, EV_PED, EV_OFFROAD, EV_RED (_sim/common.pxd)
STATIC_COLOR = "#9c9c9c"
PED_COLOR = "#e0117f"
BACKGROUND = (255, 255, 255)
DEFAULT_REGION = 200.0  # [m] edge of the spawn region (section 2.2)
DEFAULT_FOLLOW_VIEW = 80.0  # [m] edge of the follow camera's window
_EVENT_SHORT = {
    "collision": "collision",
    "pedestrian_collision": "ped hit",
    "offroad": "offroad",
    "red_light": "red light",
    "waypoint": "waypoint",
    "comfort": "comfort",
    "terminated": "terminated",
    "truncated": "truncated",
}


def box_corners(
    xy: np.ndarray, cos: np.ndarray, sin: np.ndarray, length: np.ndarray, width: np.ndarray
) -> np.ndarray:
    """Corners of oriented boxes, counter-clockwise from front-left.

    Args:
        xy: (n, 2) centres [m]; cos, sin: (n,) of the heading; length, width: (n,) [m].

    Returns:
        (n, 4, 2) float64 corners [m].
    """
    hl, hw = 0.5 * np.asarray(length, np.float64), 0.5 * np.asarray(width, np.float64)
    local = np.stack(
        [np.stack([hl, hw], 1), np.stack([-hl, hw], 1), np.stack([-hl, -hw], 1), np.stack([hl, -hw], 1)], 1
    )
    return _rotate(local, cos, sin) + np.asarray(xy, np.float64)[:, None, :]


def _rotate(local: np.ndarray, cos: np.ndarray, sin: np.ndarray) -> np.ndarray:
    c, s = np.asarray(cos, np.float64)[:, None], np.asarray(sin, np.float64)[:, None]
    return np.stack([c * local[..., 0] - s * local[..., 1], s * local[..., 0] + c * local[..., 1]], -1)


def _noses(xy: np.ndarray, heading: np.ndarray, length: np.ndarray, width: np.ndarray) -> np.ndarray:
    """(n, 3, 2) heading triangles: tip at the front bumper's centre, base inside the front half."""
    hl, hw = 0.5 * np.asarray(length, np.float64), 0.5 * np.asarray(width, np.float64)
    base = hl - np.minimum(0.8 * hl, 1.4 * hw)
    local = np.stack(
        [np.stack([hl, 0 * hl], 1), np.stack([base, 0.7 * hw], 1), np.stack([base, -0.7 * hw], 1)], 1
    )
    return _rotate(local, np.cos(heading), np.sin(heading)) + xy[:, None, :]


class MapLayer:
    """The static map drawn once into an RGB raster on a fixed pixel grid.

    Pixel column i covers x in [i / ppm, (i + 1) / ppm) (global grid), so any camera window
    snapped to the same grid is an exact integer-offset crop.

    Args:
        road_map: The map.
        extent: (xmin, ymin, xmax, ymax) [m] to cover (grown to whole pixels).
        ppm: Pixels per metre.

    Attributes:
        image: (H, W, 4) uint8 RGBA raster (opaque), row 0 at the top (largest y).
    """

    def __init__(self, road_map: RoadMap, extent: Sequence[float], ppm: float) -> None:
        self.ppm = float(ppm)
        eps = 1e-6  # extents built from grid pixels must map back to the same pixels
        self.i0 = int(np.floor(extent[0] * ppm + eps))  # first column on the global grid
        self.j0 = int(np.ceil(extent[3] * ppm - eps))  # global row index of the top edge (y up)
        width = int(np.ceil(extent[2] * ppm - eps)) - self.i0
        height = self.j0 - int(np.floor(extent[1] * ppm + eps))
        self.image = _draw_raster(road_map, self.i0, self.j0, width, height, self.ppm)

    def covers(self, i0: int, j0: int, w: int, h: int) -> bool:
        """Whether the window with global top-left pixel (i0, j0) and size w x h lies inside."""
        H, W = self.image.shape[:2]
        return i0 >= self.i0 and i0 + w <= self.i0 + W and j0 <= self.j0 and self.j0 - j0 + h <= H

    def crop_into(self, out: np.ndarray, i0: int, j0: int) -> None:
        """Copy the window with global top-left pixel (i0, j0) into `out` (h, w, 4) uint8 RGBA;
        parts outside the raster get the background colour."""
        h, w = out.shape[:2]
        H, W = self.image.shape[:2]
        c0, r0 = i0 - self.i0, self.j0 - j0
        cs, ce, rs, re = max(c0, 0), min(c0 + w, W), max(r0, 0), min(r0 + h, H)
        if not (cs == c0 and rs == r0 and ce - cs == w and re - rs == h):
            out[...] = (*BACKGROUND, 255)  # the window leaves the raster
        if cs < ce and rs < re:
            out[rs - r0 : re - r0, cs - c0 : ce - c0] = self.image[rs:re, cs:ce]


def _draw_raster(road_map: RoadMap, i0: int, j0: int, width: int, height: int, ppm: float) -> np.ndarray:
    dpi = 100.0
    fig = Figure(figsize=(width / dpi, height / dpi), dpi=dpi, facecolor="white")
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    region = (i0 / ppm, (j0 - height) / ppm, (i0 + width) / ppm, j0 / ppm)
    draw_map(ax, road_map, region=region, legend=False, lights=False)
    ax.set_aspect("auto")  # the figure already has the region's aspect; keep pixels exact
    ax.set_xlim(region[0], region[2])
    ax.set_ylim(region[1], region[3])
    ax.set_axis_off()
    canvas.draw()
    img = np.asarray(canvas.buffer_rgba())
    out = np.empty((height, width, 4), dtype=np.uint8)
    out[...] = (*BACKGROUND, 255)
    h, w = min(height, img.shape[0]), min(width, img.shape[1])  # Agg rounds sizes down at most
    out[:h, :w] = img[:h, :w]
    return out


class EpisodeRenderer:
    """Draws `WorldFrame`s to RGB images (H = W = `size` pixels).

    Args:
        maps: The maps frames refer to (`Recording.maps`).
        size: Image edge [px].
        follow: Agent slot (in the world, 0..A-1) the camera follows; None: the world's fixed
            spawn region.
        view: Edge of the camera window [m]; default the region (200 m) or 80 m when following.
        tail: Length of the trajectory tails [steps].
        waypoints: Draw waypoints.
        text: Draw the time stamp, event counts and scale bar.

    Raises:
        ValueError: On a non-positive size, view or tail, or a negative follow index.
    """

    def __init__(
        self,
        maps: Sequence[RoadMap],
        size: int = 800,
        follow: int | None = None,
        view: float | None = None,
        tail: int = 30,
        waypoints: bool = True,
        text: bool = True,
    ) -> None:
        if int(size) != size or not 64 <= size <= 8192:
            raise ValueError(f"size: expected an integer number of pixels in [64, 8192], got {size!r}")
        if view is not None and not (np.isfinite(view) and view > 0):
            raise ValueError(f"view: expected a positive window edge in metres, got {view!r}")
        if follow is not None and (int(follow) != follow or follow < 0):
            raise ValueError(f"follow: expected an agent slot index >= 0, got {follow!r}")
        if int(tail) != tail or tail < 0:
            raise ValueError(f"tail: expected an integer number of steps >= 0, got {tail!r}")
        self.maps = list(maps)
        self.size = int(size)
        self.follow = None if follow is None else int(follow)
        self.view = view
        self.tail = int(tail)
        self.show_waypoints = waypoints
        self.show_text = text
        self._layers: OrderedDict[tuple, MapLayer] = OrderedDict()
        self._camera: tuple[float, float] | None = None
        self._light_lines: dict[int, tuple[list[np.ndarray], np.ndarray]] = {}
        self._setup_figure()

    # set-up ----------------------------------------------------------------------------------
    def _setup_figure(self) -> None:
        dpi = 100.0
        self.fig = Figure(figsize=(self.size / dpi, self.size / dpi), dpi=dpi)
        self.canvas = FigureCanvasAgg(self.fig)
        ax = self.ax = self.fig.add_axes((0.0, 0.0, 1.0, 1.0))
        ax.set_axis_off()
        ax.patch.set_visible(False)
        self.pt = 72.0 / dpi  # points per pixel
        self.lights = LineCollection([], capstyle="butt")
        self.tails = LineCollection([], alpha=0.8)
        self.routes = LineCollection([], linestyles=(0, (3, 3)), alpha=0.55)
        star = MarkerStyle("*")
        path = star.get_path().transformed(star.get_transform())
        # as in Axes.scatter: marker in points (sizes), placed at data offsets
        self.wp_now = PathCollection([path], offset_transform=ax.transData, transform=IdentityTransform())
        self.wp_rest = PathCollection([path], offset_transform=ax.transData, transform=IdentityTransform())
        self.statics = PolyCollection([], facecolors=STATIC_COLOR, edgecolors="#5c5c5c")
        self.agents = PolyCollection([])
        self.noses = PolyCollection([], facecolors="white", edgecolors="none")
        self.peds = PolyCollection([], facecolors=PED_COLOR, edgecolors="#5a0033")
        self.artists = [
            self.lights,
            self.tails,
            self.routes,
            self.wp_rest,
            self.wp_now,
            self.statics,
            self.agents,
            self.noses,
            self.peds,
        ]
        for a in self.artists:
            ax.add_collection(a, autolim=False)
        self.agent_colors = to_rgba_array([matplotlib.colormaps["tab20"](i % 20) for i in range(20)])
        # text is drawn by Pillow: matplotlib's text layout costs ~100 ms a frame
        font_file = matplotlib.font_manager.findfont("DejaVu Sans Mono")
        self.font = ImageFont.truetype(font_file, size=max(9, self.size // 60))
        self.canvas.draw()  # creates the renderer that draw_artist uses
        self.buffer = np.asarray(self.canvas.buffer_rgba())
        if self.buffer.shape[:2] != (self.size, self.size):
            raise RuntimeError(f"Agg canvas is {self.buffer.shape[:2]}, expected {(self.size, self.size)}")

    # camera ----------------------------------------------------------------------------------
    def view_edge(self, frame: WorldFrame) -> float:
        """Edge of the camera window [m] for `frame`."""
        if self.view is not None:
            return float(self.view)
        if self.follow is not None:
            return DEFAULT_FOLLOW_VIEW
        if frame.region is not None:
            return float(max(frame.region[2] - frame.region[0], frame.region[3] - frame.region[1]))
        return DEFAULT_REGION

    def _centre(self, frame: WorldFrame) -> tuple[float, float]:
        if self.follow is not None:
            if self.follow >= len(frame.agent_valid):
                raise ValueError(
                    f"follow: agent slot {self.follow} does not exist, "
                    f"the world has {len(frame.agent_valid)} slots (0..{len(frame.agent_valid) - 1})"
                )
            if frame.agent_valid[self.follow]:
                return tuple(frame.agent_xy[self.follow])  # type: ignore[return-value]
            if self._camera is not None:
                return self._camera
        if frame.region is not None:
            r = frame.region
            return 0.5 * (r[0] + r[2]), 0.5 * (r[1] + r[3])
        if self._camera is not None:  # unknown region: keep the first centre (no jumping)
            return self._camera
        pts = frame.agent_xy[frame.agent_valid]
        if len(pts) == 0:
            b = self.maps[frame.map_id].bounds
            return 0.5 * (b[0] + b[2]), 0.5 * (b[1] + b[3])
        lo, hi = pts.min(0), pts.max(0)
        return 0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])

    def window(self, frame: WorldFrame) -> tuple[float, float, float, int, int]:
        """Pixels per metre and the camera window snapped to the pixel grid.

        Returns:
            (ppm, xmin, ymax, i0, j0): window left and top [m], global pixel of its top left.
        """
        ppm = self.size / self.view_edge(frame)
        cx, cy = self._centre(frame)
        self._camera = (cx, cy)
        i0 = round(float(cx) * ppm - 0.5 * self.size)
        j0 = round(float(cy) * ppm + 0.5 * self.size)
        return ppm, i0 / ppm, j0 / ppm, i0, j0

    def _layer(self, frame: WorldFrame, ppm: float, i0: int, j0: int) -> MapLayer:
        for key, layer in self._layers.items():
            if key[0] == frame.map_id and layer.ppm == ppm and layer.covers(i0, j0, self.size, self.size):
                self._layers.move_to_end(key)
                return layer
        edge = self.size / ppm
        x0, y1 = i0 / ppm, j0 / ppm
        extent = [x0, y1 - edge, x0 + edge, y1]
        if self.follow is not None:  # one raster for the whole region plus a window of margin
            if frame.region is not None:
                r = frame.region
                extent = [
                    min(extent[0], r[0]),
                    min(extent[1], r[1]),
                    max(extent[2], r[2]),
                    max(extent[3], r[3]),
                ]
            extent = [extent[0] - edge, extent[1] - edge, extent[2] + edge, extent[3] + edge]
        layer = MapLayer(self.maps[frame.map_id], extent, ppm)
        self._layers[(frame.map_id, tuple(extent))] = layer
        while len(self._layers) > 3:  # memory: a follow raster is ~40 MB at 10 px/m
            self._layers.popitem(last=False)
        return layer

    # drawing ---------------------------------------------------------------------------------
    def draw(self, frame: WorldFrame, history: Sequence[WorldFrame] = ()) -> np.ndarray:
        """Draw `frame` (and the trajectory tails from `history`, oldest first, same episode).

        Returns:
            (size, size, 3) uint8 RGB image (a new array).
        """
        ppm, xmin, ymax, i0, j0 = self.window(frame)
        edge = self.size / ppm
        self._layer(frame, ppm, i0, j0).crop_into(self.buffer, i0, j0)
        self.ax.set_xlim(xmin, xmin + edge)
        self.ax.set_ylim(ymax - edge, ymax)
        px = ppm * self.pt  # points per metre
        self._set_lights(frame, px)
        self._set_agents(frame, px)
        self._set_tails(frame, history, px)
        self._set_waypoints(frame, px)
        self._set_others(frame, px)
        for artist in self.artists:
            self.ax.draw_artist(artist)
        image = Image.fromarray(self.buffer[..., :3])  # a copy: the canvas is reused
        if self.show_text:
            self._draw_text(image, frame, edge)
        return np.array(image)

    def _set_lights(self, frame: WorldFrame, px: float) -> None:
        if frame.map_id not in self._light_lines:  # the lines never change: cut them once
            m = self.maps[frame.map_id]
            cut = [m.light_lines[i] for i in range(len(m.light_lines))]
            self._light_lines[frame.map_id] = (cut, np.asarray(m.light_group, dtype=np.int64))
        lines, groups = self._light_lines[frame.map_id]
        state = np.zeros(len(groups), dtype=np.int64)
        known = groups < len(frame.light_state)
        state[known] = frame.light_state[groups[known]]
        self.lights.set_segments(lines)
        self.lights.set_colors([LIGHT_COLORS.get(int(s), LIGHT_COLORS[0]) for s in state])
        width = float(np.clip(1.0 * px, 2.5 * self.pt, 6.0))
        self.lights.set_linewidths(np.where(state == 0, 0.5 * width, width))  # off: thin dark grey

    def agent_status(self, frame: WorldFrame) -> np.ndarray:
        """(A,) status per slot: 'active', 'parked' (started parked, still driving), 'ended',
        '' for empty slots."""
        out = np.full(len(frame.agent_valid), "", dtype=object)
        out[frame.agent_valid] = "ended"
        out[frame.agent_active] = "active"
        out[frame.agent_active & frame.agent_parked] = "parked"
        return out

    def _set_agents(self, frame: WorldFrame, px: float) -> None:
        valid = frame.agent_valid
        xy, h = frame.agent_xy[valid], frame.agent_heading[valid]
        length, width = frame.agent_length[valid], frame.agent_width[valid]
        self.agents.set_verts(box_corners(xy, np.cos(h), np.sin(h), length, width))
        status = self.agent_status(frame)[valid]
        face = to_rgba_array([STATUS_COLORS[s] for s in status]) if len(status) else np.zeros((0, 4))
        removed = (status == "ended") & ~frame.agent_obstacle[valid]
        face[removed, 3] = 0.0  # a removed car: a hollow outline where it ended
        edge = np.tile(to_rgba("black"), (len(status), 1))
        widths = np.where(removed, 1.0, 0.6)
        if self.follow is not None and self.follow < len(valid) and valid[self.follow]:
            k = int(np.count_nonzero(valid[: self.follow]))
            edge[k], widths[k] = to_rgba("#ffb000"), 2.0  # the followed car
        incident = (frame.agent_events[valid] & INCIDENT_BITS) != 0
        edge[incident], widths[incident] = to_rgba(INCIDENT_COLOR), 2.0
        self.agents.set_facecolors(face)
        self.agents.set_edgecolors(edge)
        self.agents.set_linewidths(widths)
        driving = frame.agent_active[valid]
        self.noses.set_verts(_noses(xy[driving], h[driving], length[driving], width[driving]))

    def _agent_colors(self, count: int) -> np.ndarray:
        """(count, 4) RGBA: one tab20 colour per agent slot (cycled)."""
        return self.agent_colors[np.arange(count) % len(self.agent_colors)]

    def _set_tails(self, frame: WorldFrame, history: Sequence[WorldFrame], px: float) -> None:
        past = [f for f in history if f.episode == frame.episode][-self.tail :] if self.tail else []
        seq = [*past, frame] if self.tail else []
        if len(seq) < 2:
            self.tails.set_segments([])
            return
        xy = np.stack([f.agent_xy for f in seq])  # (T, A, 2)
        live = np.stack([f.agent_active | f.agent_obstacle for f in seq])  # (T, A)
        colors = self._agent_colors(xy.shape[1])
        segs, cols = [], []
        for a in np.flatnonzero(frame.agent_valid):
            pts = xy[live[:, a], a]
            if len(pts) >= 2:
                segs.append(pts)
                cols.append(colors[a])
        self.tails.set_segments(segs)
        self.tails.set_colors(cols)
        self.tails.set_linewidth(float(np.clip(0.5 * px, 0.8, 3.0)))

    def _set_waypoints(self, frame: WorldFrame, px: float) -> None:
        for c in (self.routes, self.wp_now, self.wp_rest):
            c.set_visible(self.show_waypoints)
        if not self.show_waypoints:
            return
        colors = self._agent_colors(len(frame.agent_valid))
        agents = np.flatnonzero(frame.agent_active & (frame.wp_idx < frame.num_wp))
        k = frame.wp_idx[agents]
        now = frame.waypoints[agents, k].astype(np.float64)
        # remaining: slots after the current one and below num_wp, as one masked gather
        slot = np.arange(frame.waypoints.shape[1])
        later = (slot[None, :] > k[:, None]) & (slot[None, :] < frame.num_wp[agents, None])
        rest = frame.waypoints[agents][later].astype(np.float64)
        owner = np.broadcast_to(agents[:, None], later.shape)[later]
        star = float(np.clip(2.2 * px, 4.0, 18.0))  # marker edge [pt]: ~2 m wide at 4 px/m
        self.wp_now.set_offsets(now.reshape(-1, 2))
        self.wp_now.set_sizes([star**2])
        self.wp_now.set_facecolors(colors[agents])
        self.wp_now.set_edgecolors("black")
        self.wp_now.set_linewidths(0.6)
        self.wp_rest.set_offsets(rest.reshape(-1, 2))
        self.wp_rest.set_sizes([(0.6 * star) ** 2])
        self.wp_rest.set_facecolors(colors[owner])
        self.wp_rest.set_edgecolors("none")
        # a thin dashed line from each car to its current waypoint says whose star it is
        self.routes.set_segments(np.stack([frame.agent_xy[agents], now], axis=1))
        self.routes.set_colors(colors[agents])
        self.routes.set_linewidth(0.8)

    def _set_others(self, frame: WorldFrame, px: float) -> None:
        s = frame.static_valid
        self.statics.set_verts(
            box_corners(
                frame.static_xy[s],
                frame.static_cos[s],
                frame.static_sin[s],
                frame.static_length[s],
                frame.static_width[s],
            )
        )
        self.statics.set_linewidths(0.5)
        p = frame.ped_present
        # drawn at least 1.2 m wide so that a pedestrian stays visible over a 200 m region
        side = np.maximum(np.maximum(frame.ped_length[p], frame.ped_width[p]), 1.2)
        self.peds.set_verts(box_corners(frame.ped_xy[p], frame.ped_cos[p], frame.ped_sin[p], side, side))
        self.peds.set_linewidths(0.5)

    def _draw_text(self, image: Image.Image, frame: WorldFrame, edge: float) -> None:
        status = self.agent_status(frame)
        n_act = int(np.count_nonzero((status == "active") | (status == "parked")))
        n_end = int(np.count_nonzero(status == "ended"))
        clock = (
            f"t = {frame.time:5.1f} s  frame {frame.index}  episode {frame.episode}\n"
            f"agents {n_act} driving, {n_end} ended  peds {int(frame.ped_present.sum())}"
        )
        ev = [f"{_EVENT_SHORT[n]} {int(v)}" for n, v in zip(EVENT_NAMES, frame.events, strict=True)]
        counts = "  ".join(ev[:4]) + "\n" + "  ".join(ev[4:])
        draw = ImageDraw.Draw(image)
        pad = max(2, self.size // 200)
        _label(image, draw, (pad, pad), clock, self.font, "top")
        _label(image, draw, (pad, self.size - pad), counts, self.font, "bottom")
        bar = _nice_length(0.2 * edge)  # a round length about a fifth of the window
        bar_px = round(bar * self.size / edge)
        x1, y = self.size - 3 * pad, self.size - 3 * pad
        draw.rectangle((x1 - bar_px, y - 3, x1, y), fill="black")
        draw.text((x1 - bar_px / 2, y - 5), f"{bar:g} m", fill="black", font=self.font, anchor="md")

    # whole recordings --------------------------------------------------------------------------
    def frames(self, recording: Recording, every: int = 1) -> Iterator[np.ndarray]:
        """Images of every `every`-th frame of `recording`, tails from the frames before."""
        if int(every) != every or every < 1:
            raise ValueError(f"every: expected an integer >= 1, got {every!r}")
        history: deque[WorldFrame] = deque(maxlen=max(self.tail, 1))
        for i, frame in enumerate(recording.frames):
            if i % every == 0:
                yield self.draw(frame, list(history))
            history.append(frame)


def _label(
    image: Image.Image, draw: ImageDraw.ImageDraw, xy: tuple[int, int], text: str, font, side: str
) -> None:
    """Multi-line `text` on a translucent white box; `xy` is the top-left (side 'top') or the
    bottom-left (side 'bottom') corner."""
    x0, y0, x1, y1 = draw.multiline_textbbox((0, 0), text, font=font)
    w, h = x1 - x0 + 6, y1 - y0 + 6
    left, top = xy[0], xy[1] if side == "top" else xy[1] - h
    arr = np.asarray(image)  # read-only view: blend a copy of the box and paste it back
    box = arr[top : top + h, left : left + w].astype(np.uint16)
    box = ((box + 4 * 255) // 5).astype(np.uint8)  # 80 % white over the map
    image.paste(Image.fromarray(box), (left, top))
    draw.multiline_text((left + 3 - x0, top + 3 - y0), text, fill="black", font=font)


def _nice_length(x: float) -> float:
    """Largest of 1, 2, 5 x 10^k not above `x` (> 0)."""
    k = 10.0 ** np.floor(np.log10(x))
    return float(max(m * k for m in (1, 2, 5) if m * k <= x))
