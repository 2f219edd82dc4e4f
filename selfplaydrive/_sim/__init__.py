"""Private Cython kernels: nogil, struct-of-arrays, parallel over worlds. Not a public API.

OpenMP threads wait passively (sleep) between parallel regions unless the user chose a policy:
the default GNU policy spins for a while after every step, and a spinning worker steals the
core that Python (action sampling, the trainer) needs between steps, which made 2 threads
slower than 1 on 2 cores. The variable must be set before libgomp initialises, that is before
the first kernel module is imported; `OMP_WAIT_POLICY=active` in the environment overrides it.
"""

import os

os.environ.setdefault("OMP_WAIT_POLICY", "passive")
