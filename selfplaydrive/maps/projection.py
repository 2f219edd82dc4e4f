"""Map projections for loaders: lat/lon [deg] -> planar metres, without pyproj.

Two projections are enough for the maps the project reads (paper section 2.1 trains on Tartu):

- `LocalTransverseMercator`: an ellipsoidal transverse Mercator (WGS84, scale 1) centred on the
  map, for files that carry only lat/lon (the Lanelet2 example, CARLA towns). Within a few
  kilometres of the centre its scale error is below 1e-6, i.e. millimetres on a city map.
- `lest97`: the Estonian grid L-EST97 (EPSG:3301, Lambert conformal conic on GRS80). Tartu's
  Lanelet2 files store `local_x`/`local_y` = L-EST97 minus (650000, 6465000); the loader
  recognises that by projecting the node's lat/lon and comparing.

Formulas: J. P. Snyder, "Map Projections: A Working Manual", USGS PP 1395 (1987), chapters 8
(transverse Mercator, eq. 8-9/8-10) and 15 (Lambert conformal conic, eq. 15-1 .. 15-10).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

WGS84_A = 6378137.0  # [m] semi-major axis
WGS84_F = 1.0 / 298.257223563
GRS80_A = 6378137.0  # [m]
GRS80_F = 1.0 / 298.257222101

# EPSG:3301 parameters (degrees, metres)
LEST97_LAT1 = 59.0 + 20.0 / 60.0
LEST97_LAT2 = 58.0
LEST97_LAT0 = 57.51755393055556
LEST97_LON0 = 24.0
LEST97_FALSE_EASTING = 500000.0
LEST97_FALSE_NORTHING = 6375000.0


def _meridian_arc(phi: np.ndarray, a: float, e2: float) -> np.ndarray:
    """Distance along the meridian from the equator to latitude `phi` [rad] (Snyder 3-21) [m]."""
    e4, e6 = e2 * e2, e2 * e2 * e2
    return a * (
        (1 - e2 / 4 - 3 * e4 / 64 - 5 * e6 / 256) * phi
        - (3 * e2 / 8 + 3 * e4 / 32 + 45 * e6 / 1024) * np.sin(2 * phi)
        + (15 * e4 / 256 + 45 * e6 / 1024) * np.sin(4 * phi)
        - (35 * e6 / 3072) * np.sin(6 * phi)
    )


@dataclass(frozen=True)
class LocalTransverseMercator:
    """Transverse Mercator on WGS84 with its origin (x=0, y=0) at (`lat0`, `lon0`) [deg], scale 1.

    Attributes:
        lat0: Latitude of the origin [deg].
        lon0: Central meridian [deg].
    """

    lat0: float
    lon0: float

    @property
    def crs(self) -> str:
        """PROJ-style description of this projection."""
        return f"+proj=tmerc +lat_0={self.lat0:.9f} +lon_0={self.lon0:.9f} +k=1 +x_0=0 +y_0=0 +ellps=WGS84"

    def forward(self, lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
        """Project (n,) lat/lon [deg] to (n, 2) x east / y north [m]."""
        a, f = WGS84_A, WGS84_F
        e2 = f * (2 - f)
        ep2 = e2 / (1 - e2)
        phi = np.radians(np.asarray(lat, dtype=np.float64))
        dlam = np.radians(np.asarray(lon, dtype=np.float64) - self.lon0)
        sin, cos, tan = np.sin(phi), np.cos(phi), np.tan(phi)
        n = a / np.sqrt(1 - e2 * sin * sin)
        t = tan * tan
        c = ep2 * cos * cos
        aa = dlam * cos
        m = _meridian_arc(phi, a, e2)
        m0 = _meridian_arc(np.radians(self.lat0), a, e2)
        x = n * (aa + (1 - t + c) * aa**3 / 6 + (5 - 18 * t + t * t + 72 * c - 58 * ep2) * aa**5 / 120)
        y = (
            m
            - m0
            + n
            * tan
            * (
                aa**2 / 2
                + (5 - t + 9 * c + 4 * c * c) * aa**4 / 24
                + (61 - 58 * t + t * t + 600 * c - 330 * ep2) * aa**6 / 720
            )
        )
        return np.stack([x, y], axis=-1)


def _lcc_t(phi: np.ndarray, e: float) -> np.ndarray:
    s = np.sin(phi)
    return np.tan(np.pi / 4 - phi / 2) / ((1 - e * s) / (1 + e * s)) ** (e / 2)


def _lcc_m(phi: float, e2: float) -> float:
    return float(np.cos(phi) / np.sqrt(1 - e2 * np.sin(phi) ** 2))


def lest97(lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
    """Project (n,) lat/lon [deg] (GRS80 ~ WGS84) to (n, 2) L-EST97 easting/northing [m].

    Returns (easting, northing), i.e. x east, y north (EPSG:3301 lists northing first).
    """
    a, f = GRS80_A, GRS80_F
    e2 = f * (2 - f)
    e = np.sqrt(e2)
    p1, p2, p0 = np.radians([LEST97_LAT1, LEST97_LAT2, LEST97_LAT0])
    m1, m2 = _lcc_m(p1, e2), _lcc_m(p2, e2)
    t1, t2, t0 = _lcc_t(p1, e), _lcc_t(p2, e), _lcc_t(p0, e)
    n = (np.log(m1) - np.log(m2)) / (np.log(t1) - np.log(t2))
    big_f = m1 / (n * t1**n)
    rho0 = a * big_f * t0**n
    phi = np.radians(np.asarray(lat, dtype=np.float64))
    rho = a * big_f * _lcc_t(phi, e) ** n
    theta = n * np.radians(np.asarray(lon, dtype=np.float64) - LEST97_LON0)
    east = LEST97_FALSE_EASTING + rho * np.sin(theta)
    north = LEST97_FALSE_NORTHING + rho0 - rho * np.cos(theta)
    return np.stack([east, north], axis=-1)
