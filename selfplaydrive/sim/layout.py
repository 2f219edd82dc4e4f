"""Re-export of `selfplaydrive.obs.layout` (the layout lives with the observation encoders;
this module keeps `from selfplaydrive.sim.layout import ObsLayout` working)."""

from selfplaydrive.obs.layout import EGO_FEATURES, OBJECT_FEATURES, ROAD_FEATURES, ObsLayout

__all__ = ["EGO_FEATURES", "OBJECT_FEATURES", "ROAD_FEATURES", "ObsLayout"]
