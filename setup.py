"""Build the Cython extensions under selfplaydrive/_sim (every .pyx there is one module).

Environment switches:
    SELFPLAYDRIVE_DEBUG_CYTHON=1  bounds checking and wraparound on (debug build, used in tests).
    SELFPLAYDRIVE_NO_OPENMP=1     build without OpenMP (stepping then runs on one thread).
"""

import glob
import os
import sys

import numpy as np
from Cython.Build import cythonize
from setuptools import Extension, setup

DEBUG = os.environ.get("SELFPLAYDRIVE_DEBUG_CYTHON") == "1"
OPENMP = os.environ.get("SELFPLAYDRIVE_NO_OPENMP") != "1" and sys.platform != "darwin"

compile_args = ["-O3", "-fno-fast-math", "-ffp-contract=off"]
link_args = []
if OPENMP:
    compile_args.append("-fopenmp")
    link_args.append("-fopenmp")
else:
    print("selfplaydrive: building WITHOUT OpenMP; stepping will use one thread", file=sys.stderr)

extensions = [
    Extension(
        path[:-4].replace(os.sep, "."),
        [path],
        include_dirs=[np.get_include(), "selfplaydrive/_sim", "selfplaydrive/include"],
        define_macros=[("NPY_NO_DEPRECATED_API", "NPY_1_22_API_VERSION")],
        extra_compile_args=compile_args,
        extra_link_args=link_args,
    )
    for path in sorted(glob.glob(os.path.join("selfplaydrive", "_sim", "*.pyx")))
]

directives = {
    "language_level": 3,
    "boundscheck": DEBUG,
    "wraparound": DEBUG,
    "initializedcheck": DEBUG,
    "nonecheck": False,
    "cdivision": True,
    "embedsignature": True,
}

# selfplaydrive/include: the component ABI (selfplaydrive_abi.h/.pxd), shipped for plug-ins
include_path = ["selfplaydrive/_sim", "selfplaydrive/include"]
setup(ext_modules=cythonize(extensions, compiler_directives=directives, include_path=include_path))
