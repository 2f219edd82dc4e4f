# cython: language_level=3
"""Building blocks shared by the spawner kernels (_sim/lanes.pyx, waypoints.pyx, placement.pyx,
pedestrians.pyx, samplers.pyx): scratch allocation, the world generator's C interface, output
fields, grid-cell queries, vehicle sizes and angle wrapping (the lane-piece search is
map-level: lanes.pxd).

Every function is inline: each module compiles its own copy, so no candidate loop calls
across modules.
"""

cimport numpy as cnp
from cpython.pycapsule cimport PyCapsule_GetPointer
from libc.math cimport fmod
from libc.stdlib cimport malloc
from numpy.random cimport bitgen_t

from selfplaydrive._sim.lanes cimport f64, i64, u64


cdef inline void* _alloc(size_t nbytes) except NULL:
    """malloc that raises MemoryError (at least one byte, so zero-size scratch is valid)."""
    cdef void* p = malloc(nbytes if nbytes > 0 else 1)
    if p == NULL:
        raise MemoryError(f"spawn kernel scratch of {nbytes} bytes")
    return p


cdef inline bitgen_t* _bitgen(object rng) except NULL:
    """The C bit generator of a `numpy.random.Generator`: `next_double` continues its stream
    exactly as `rng.random` does, so a kernel can draw lazily, one candidate at a time. Callers
    hold `rng.bit_generator.lock` while drawing."""
    return <bitgen_t*>PyCapsule_GetPointer(rng.bit_generator.capsule, "BitGenerator")


cdef inline void _draw(bitgen_t* bg, double* u, Py_ssize_t n) noexcept nogil:
    """n uniforms in [0, 1) into u (the next n values of `rng.random`)."""
    cdef Py_ssize_t i
    for i in range(n):
        u[i] = bg.next_double(bg.state)


cdef inline void* _field(object sc, str name, int typenum, Py_ssize_t size) except NULL:
    """Data pointer of the output array `sc.name` (a `Scenario` or `PedestrianBatch` field)
    after checking its dtype, layout and size."""
    arr = getattr(sc, name)
    if (not isinstance(arr, cnp.ndarray) or cnp.PyArray_TYPE(<cnp.ndarray>arr) != typenum
            or not cnp.PyArray_IS_C_CONTIGUOUS(<cnp.ndarray>arr)
            or not cnp.PyArray_ISWRITEABLE(<cnp.ndarray>arr) or cnp.PyArray_SIZE(<cnp.ndarray>arr) < size):
        raise ValueError(
            f"{type(sc).__name__}.{name} must be a writable C-contiguous {cnp.PyArray_DescrFromType(typenum)} "
            f"array of at least {size} entries, got {type(arr).__name__} "
            f"{getattr(arr, 'dtype', '')} {getattr(arr, 'shape', '')}"
        )
    return cnp.PyArray_DATA(<cnp.ndarray>arr)


cdef inline bint _box_cells(const f64[::1] cell_origin, double cell, Py_ssize_t nx, Py_ssize_t ny,
                            const f64[::1] box, Py_ssize_t* r) noexcept nogil:
    """Grid cells that meet `box`: r = [ix0, iy0, ix1, iy1] (inclusive); False when none."""
    r[0] = max(0, <Py_ssize_t>((box[0] - cell_origin[0]) // cell))
    r[1] = max(0, <Py_ssize_t>((box[1] - cell_origin[1]) // cell))
    r[2] = min(nx - 1, <Py_ssize_t>((box[2] - cell_origin[0]) // cell))
    r[3] = min(ny - 1, <Py_ssize_t>((box[3] - cell_origin[1]) // cell))
    return r[2] >= r[0] and r[3] >= r[1]


cdef inline Py_ssize_t _box_count(const f64[::1] cell_origin, double cell, Py_ssize_t nx, Py_ssize_t ny,
                           const i64[::1] cell_offsets, const f64[::1] box) noexcept:
    """Number of items in the cells that meet `box` (an upper bound of the chunks inside)."""
    cdef Py_ssize_t r[4]
    cdef Py_ssize_t i, k = 0
    if not _box_cells(cell_origin, cell, nx, ny, box, r):
        return 0
    for i in range(r[0], r[2] + 1):
        k += cell_offsets[i * ny + r[3] + 1] - cell_offsets[i * ny + r[1]]
    return k


cdef inline i64 _size(const f64[::1] cdf, const f64[::1] length_tab, const f64[::1] width_tab,
                      double jitter, double max_width, double u0, double u1, double u2,
                      double* length, double* width) noexcept nogil:
    """One vehicle size: category = first cdf entry above u0 (capped at the last), length and
    width scaled by 1 - jitter + 2 jitter u1 and u2, width capped at max_width; returns the
    category."""
    cdef i64 c = 0, K = cdf.shape[0]
    cdef double a = 1.0 - jitter, b = 2.0 * jitter, w
    while c < K and cdf[c] <= u0:  # searchsorted(cdf, u0, side="right")
        c += 1
    if c > K - 1:
        c = K - 1
    length[0] = length_tab[c] * (a + b * u1)
    w = width_tab[c] * (a + b * u2)
    width[0] = w if w < max_width else max_width  # np.minimum (max_width is finite)
    return c


cdef inline double _wrap_angle(double a) noexcept nogil:
    """NumPy's (a + pi) % (2 pi) - pi (float remainder: fmod with the sign of the divisor)."""
    cdef double b = 6.283185307179586, mod = fmod(a + 3.141592653589793, b)
    if mod != 0.0:
        if mod < 0.0:
            mod = mod + b
    else:
        mod = 0.0
    return mod - 3.141592653589793
