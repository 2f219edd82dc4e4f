"""OpenDRIVE reference-line geometry: line, arc, spiral, poly3, paramPoly3 (plan view).

All functions are vectorised over the distance `ds` [m] from the start of a geometry record and
return global x, y [m] and heading [rad]. Integrals without a closed form (the clothoid's
position, the poly3 arc length) use composite 5-point Gauss-Legendre quadrature on steps short
enough that the heading changes by at most `MAX_TURN_PER_STEP`, which is exact to ~1e-10 m on
road-scale geometry and never loops more than `MAX_STEPS` times (corrupt input cannot hang).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from selfplaydrive.errors import MapError
from selfplaydrive.maps.opendrive.parse import Geometry, Poly

MAX_TURN_PER_STEP = 0.05  # [rad] heading change per quadrature step
MAX_STEPS = 200_000  # cap on quadrature steps per geometry record
_GL_X, _GL_W = np.polynomial.legendre.leggauss(5)


def _cumulative_integral(
    f: Callable[[np.ndarray], np.ndarray], length: float, step: float
) -> tuple[np.ndarray, np.ndarray]:
    """Nodes 0..length and the integral of `f` from 0 to each node (5-point Gauss-Legendre).

    Returns:
        (nodes, cum): two (n + 1,) arrays; f may return shape (m, k) for k stacked integrands,
        then cum has shape (n + 1, k).
    """
    n = int(min(MAX_STEPS, max(1, np.ceil(length / max(step, 1e-12)))))
    nodes = np.linspace(0.0, length, n + 1)
    h = length / n
    mids = nodes[:-1, None] + 0.5 * h * (_GL_X[None, :] + 1.0)  # (n, 5)
    vals = f(mids.ravel())
    vals = vals.reshape(n, 5, -1)
    per_step = 0.5 * h * np.einsum("nqk,q->nk", vals, _GL_W)
    cum = np.concatenate([np.zeros((1, per_step.shape[1])), np.cumsum(per_step, axis=0)])
    return nodes, cum


def _integral_at(
    f: Callable[[np.ndarray], np.ndarray], nodes: np.ndarray, cum: np.ndarray, ds: np.ndarray
) -> np.ndarray:
    """Integral of `f` from 0 to each ds: table value at the node below plus one GL step."""
    k = np.clip(np.searchsorted(nodes, ds, side="right") - 1, 0, len(nodes) - 2)
    a = nodes[k]
    half = 0.5 * (ds - a)
    x = a[:, None] + half[:, None] * (_GL_X[None, :] + 1.0)
    vals = f(x.ravel()).reshape(len(ds), 5, -1)
    return cum[k] + half[:, None] * np.einsum("nqk,q->nk", vals, _GL_W)


def _rotate(g: Geometry, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    c, s = np.cos(g.hdg), np.sin(g.hdg)
    return g.x + u * c - v * s, g.y + u * s + v * c


def _line(g: Geometry, ds: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return g.x + ds * np.cos(g.hdg), g.y + ds * np.sin(g.hdg), np.full_like(ds, g.hdg)


def _arc(g: Geometry, ds: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    k = float(g.params["curvature"])
    if abs(k) < 1e-12:
        return _line(g, ds)
    h = g.hdg + k * ds
    return g.x + (np.sin(h) - np.sin(g.hdg)) / k, g.y - (np.cos(h) - np.cos(g.hdg)) / k, h


def _spiral(g: Geometry, ds: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Clothoid: curvature linear in ds from curvStart to curvEnd over the record's length."""
    k0, k1 = float(g.params["curvStart"]), float(g.params["curvEnd"])
    rate = (k1 - k0) / g.length if g.length > 0 else 0.0

    def heading(s: np.ndarray) -> np.ndarray:
        return g.hdg + k0 * s + 0.5 * rate * s * s

    def integrand(s: np.ndarray) -> np.ndarray:
        h = heading(s)
        return np.stack([np.cos(h), np.sin(h)], axis=-1)

    kmax = max(abs(k0), abs(k1), 1e-9)
    nodes, cum = _cumulative_integral(integrand, g.length, min(1.0, MAX_TURN_PER_STEP / kmax))
    xy = _integral_at(integrand, nodes, cum, ds)
    return g.x + xy[:, 0], g.y + xy[:, 1], heading(ds)


def _poly3(g: Geometry, ds: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cubic v(u) in the local frame; ds is arc length, so u(ds) comes from inverting s(u)."""
    a, b, c, d = (float(g.params[n]) for n in "abcd")

    def dv(u: np.ndarray) -> np.ndarray:
        return b + 2.0 * c * u + 3.0 * d * u * u

    def speed(u: np.ndarray) -> np.ndarray:
        return np.sqrt(1.0 + dv(u) ** 2)[:, None]

    # arc length s(u) >= u, so u(length) <= length: tabulate s(u) on [0, length] and invert
    nodes, cum = _cumulative_integral(speed, max(g.length, 1e-9), 0.1)
    u = np.interp(ds, cum[:, 0], nodes)
    v = a + b * u + c * u * u + d * u**3
    x, y = _rotate(g, u, v)
    return x, y, g.hdg + np.arctan(dv(u))


def _param_poly3(g: Geometry, ds: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """u(p), v(p) cubic in p; p = ds for pRange="arcLength", ds / length for "normalized"."""
    p = ds if g.params["pRange"] == "arcLength" else ds / max(g.length, 1e-12)
    cu = [float(g.params[n]) for n in ("aU", "bU", "cU", "dU")]
    cv = [float(g.params[n]) for n in ("aV", "bV", "cV", "dV")]
    u = cu[0] + cu[1] * p + cu[2] * p * p + cu[3] * p**3
    v = cv[0] + cv[1] * p + cv[2] * p * p + cv[3] * p**3
    du = cu[1] + 2.0 * cu[2] * p + 3.0 * cu[3] * p * p
    dv = cv[1] + 2.0 * cv[2] * p + 3.0 * cv[3] * p * p
    x, y = _rotate(g, u, v)
    return x, y, g.hdg + np.arctan2(dv, du)


_EVAL = {"line": _line, "arc": _arc, "spiral": _spiral, "poly3": _poly3, "paramPoly3": _param_poly3}


def eval_geometry(g: Geometry, ds: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position x, y [m] and heading [rad] at distances `ds` [m] (shape (n,)) along `g`."""
    return _EVAL[g.kind](g, np.asarray(ds, dtype=np.float64))


class ReferenceLine:
    """A road's plan view: sorted geometry records evaluated at any s [m].

    Args:
        geometries: Records sorted by s.
        path, element: For error messages.
    """

    def __init__(self, geometries: Sequence[Geometry], path: str = "", element: str = "") -> None:
        self.geometries = list(geometries)
        self.starts = np.array([g.s for g in self.geometries])
        self.path, self.element = path, element

    def evaluate(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """x, y [m] and heading [rad] at road positions `s` [m], shape (n,) each.

        Positions past a record's end stay on that record (clamped), so a rounding gap at a
        record boundary does not extrapolate a curve.
        """
        s = np.asarray(s, dtype=np.float64)
        idx = np.clip(np.searchsorted(self.starts, s, side="right") - 1, 0, len(self.geometries) - 1)
        x, y, h = np.empty_like(s), np.empty_like(s), np.empty_like(s)
        for i in np.unique(idx):
            g = self.geometries[i]
            m = idx == i
            ds = np.clip(s[m] - g.s, 0.0, g.length)
            x[m], y[m], h[m] = eval_geometry(g, ds)
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y)) and np.all(np.isfinite(h))):
            raise MapError("reference line evaluates to non-finite coordinates", self.path, self.element)
        return x, y, h

    def breakpoints(self) -> np.ndarray:
        """Start and end s [m] of every record (where the curvature may jump)."""
        return np.concatenate([self.starts, self.starts + [g.length for g in self.geometries]])


def eval_polys(
    polys: Sequence[Poly], s: np.ndarray, origin: float = 0.0, below: float | None = None
) -> np.ndarray:
    """Piecewise cubic: the record with the largest start <= s applies, with ds = s - start.

    Args:
        polys: Records sorted by `Poly.s`, starts relative to `origin`.
        s: (n,) positions [m] in the same frame as `origin + Poly.s`.
        origin: Offset added to every record start (the lane section start for widths).
        below: If given, records starting at or after this position are not selected (a lane
            section ending where a new laneOffset record starts keeps the old record at its
            last sample, so its lanes stay continuous).

    Returns:
        (n,) values; zeros when `polys` is empty. Before the first record its ds is clamped to 0.
    """
    s = np.asarray(s, dtype=np.float64)
    if not polys:
        return np.zeros_like(s)
    starts = np.array([origin + p.s for p in polys])
    coef = np.array([[p.a, p.b, p.c, p.d] for p in polys])
    pick = s if below is None else np.minimum(s, np.nextafter(below, -np.inf))
    idx = np.clip(np.searchsorted(starts, pick, side="right") - 1, 0, len(polys) - 1)
    ds = np.maximum(s - starts[idx], 0.0)
    c = coef[idx]
    return c[:, 0] + ds * (c[:, 1] + ds * (c[:, 2] + ds * c[:, 3]))
