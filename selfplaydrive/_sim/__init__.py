"""Private Cython kernels: nogil, struct-of-arrays, parallel over worlds. Not a public API."""
