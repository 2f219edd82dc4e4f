"""Hydra configs shipped with the package (config path `pkg://selfplaydrive.conf`)."""
