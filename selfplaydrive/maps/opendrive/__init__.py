"""OpenDRIVE (.xodr) map loader on the standard library, NumPy and Shapely (paper section 2.1).

`read_opendrive(path)` returns `MapElements`; `OpenDriveLoader(path, ...).load()` returns a
compiled `RoadMap`. See docs/maps/opendrive.md for what is read and what is ignored.
"""

from selfplaydrive.maps.opendrive.loader import DEFAULT_SPEED_LIMIT, OpenDriveLoader, read_opendrive
from selfplaydrive.maps.opendrive.parse import parse_opendrive

__all__ = ["DEFAULT_SPEED_LIMIT", "OpenDriveLoader", "parse_opendrive", "read_opendrive"]
