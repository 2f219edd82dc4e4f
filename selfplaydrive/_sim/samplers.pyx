# cython: language_level=3
"""Per-vehicle draws of the spawner (paper sections 2.2, 2.3): vehicle sizes
(`scenario.vehicles.VehicleSizeSampler`) and reward coefficients
(`scenario.conditioning.ConditioningSampler`), after their NumPy draws.
"""

import numpy as np

cimport numpy as cnp
from selfplaydrive._sim.spawn_common cimport f64, i64, _size

cnp.import_array()


def vehicle_sizes(const f64[:, ::1] u, const f64[::1] cdf, const f64[::1] length_tab,
                  const f64[::1] width_tab, double jitter, double max_width):
    """The body of `scenario.vehicles.VehicleSizeSampler.sample` after its (3, n) draw `u`
    (`_size` of each column).

    Returns:
        length (n,) float64 [m], width (n,) float64 [m], category (n,) int64.
    """
    cdef Py_ssize_t i, n = u.shape[1]
    length_arr = np.empty(n)
    width_arr = np.empty(n)
    cat_arr = np.empty(n, dtype=np.int64)
    cdef f64[::1] length = length_arr, width = width_arr
    cdef i64[::1] cat = cat_arr
    for i in range(n):
        cat[i] = _size(cdf, length_tab, width_tab, jitter, max_width, u[0, i], u[1, i], u[2, i],
                       &length[i], &width[i])
    return length_arr, width_arr, cat_arr


def bimodal_uniform(const f64[:, ::1] u, const f64[::1] lo, const f64[::1] hi, Py_ssize_t c,
                    double c_lo, double c_hi, double p_c, Py_ssize_t a, double a_lo, double a_hi,
                    double p_a):
    """The body of `scenario.conditioning.ConditioningSampler.sample` after its (n, C + 2) draw:
    coefficient k of agent i is lo_k + (hi_k - lo_k) u[i, k], where columns c and a take the
    low ranges (c_lo, c_hi), (a_lo, a_hi) when u[i, C] < p_c, u[i, C + 1] < p_a.

    Returns:
        (n, C) float32.
    """
    cdef Py_ssize_t i, k, n = u.shape[0], C = lo.shape[0]
    cdef double l, h
    out_arr = np.empty((n, C), dtype=np.float32)
    cdef cnp.float32_t[:, ::1] out = out_arr
    for i in range(n):
        for k in range(C):
            l = lo[k]
            h = hi[k]
            if k == c and u[i, C] < p_c:
                l = c_lo
                h = c_hi
            if k == a and u[i, C + 1] < p_a:
                l = a_lo
                h = a_hi
            out[i, k] = <cnp.float32_t>(l + (h - l) * u[i, k])
    return out_arr
