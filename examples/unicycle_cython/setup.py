"""Build the model's extension against the installed selfplaydrive's ABI declarations."""

from Cython.Build import cythonize
from setuptools import Extension, setup

import selfplaydrive

include = selfplaydrive.get_include()  # selfplaydrive_abi.h and selfplaydrive_abi.pxd
setup(
    ext_modules=cythonize(
        [
            Extension(
                "unicycle_physics._kernel",
                ["unicycle_physics/_kernel.pyx"],
                include_dirs=[include],
                extra_compile_args=["-O3"],
            )
        ],
        include_path=[include],
        compiler_directives={"language_level": 3, "boundscheck": False, "wraparound": False},
    )
)
