"""Top-down rendering with matplotlib (Agg): maps now, vehicles and videos on top later."""

from selfplaydrive.render.map_render import draw_map, lane_polygons, render_map

__all__ = ["draw_map", "lane_polygons", "render_map"]
