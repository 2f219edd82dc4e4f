"""Observation encoder configuration (paper section 2.5); the layout lives in sim/layout.py."""

from selfplaydrive.obs.config import ObsConfig, ObsHook

__all__ = ["ObsConfig", "ObsHook"]
