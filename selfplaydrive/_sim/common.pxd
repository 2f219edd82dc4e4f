# cython: language_level=3
"""Structs and constants shared by the simulator kernels (paper section 2).

They are the component ABI: declared once in selfplaydrive/include/selfplaydrive_abi.h (every
field with its shape and unit) and selfplaydrive_abi.pxd, which ship with the package so that
plug-in components compile against the same view (`selfplaydrive.get_include()`). The kernels
cimport them from here, as before. `world.pyx` fills the structs once and the kernels read and
write through them without the GIL.
"""

from selfplaydrive_abi cimport *
