"""Top-down rendering with matplotlib (Agg): maps (`map_render`), recorded episodes
(`record`, `episode`), PNG / GIF / MP4 output (`video`), action sources (`policies`);
docs/rendering.md."""

from selfplaydrive.render.episode import EpisodeRenderer
from selfplaydrive.render.map_render import draw_map, lane_polygons, render_map
from selfplaydrive.render.record import Recording, WorldFrame, record_episode
from selfplaydrive.render.video import render_episode, write_video

__all__ = [
    "EpisodeRenderer",
    "Recording",
    "WorldFrame",
    "draw_map",
    "lane_polygons",
    "record_episode",
    "render_episode",
    "render_map",
    "write_video",
]
