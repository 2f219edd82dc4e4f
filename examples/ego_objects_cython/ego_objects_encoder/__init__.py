"""A selfplaydrive observation encoder written in Cython: the ego's features and the k nearest
bodies within the radius, no road (the numba form is examples/09_encoder_numba.py)."""

from __future__ import annotations

from ego_objects_encoder import _kernel
from selfplaydrive.obs import KernelEncoder, ObsLayout


def ego_objects_encoder(max_objects: int = 8, radius: float = 50.0) -> KernelEncoder:
    """The encoder as a `KernelEncoder`, ready for `VecEnv(obs=...)`.

    Args:
        max_objects: k, the nearest bodies observed.
        radius: [m] observation radius and position scale.
    """
    layout = ObsLayout(max_objects=int(max_objects), max_road=0)
    return KernelEncoder.from_cython("ego_objects", _kernel, "ego_objects", layout, radius=float(radius))
