"""Hand-computed checks of the OpenDRIVE reference-line geometry and lane polynomials."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import fresnel

from selfplaydrive.maps.opendrive.geometry import ReferenceLine, eval_geometry, eval_polys
from selfplaydrive.maps.opendrive.parse import Geometry, Poly


def _end(g: Geometry) -> tuple[float, float, float]:
    x, y, h = eval_geometry(g, np.array([g.length]))
    return float(x[0]), float(y[0]), float(h[0])


def test_line_north_ends_ten_metres_up() -> None:
    g = Geometry(s=0, x=3.0, y=-2.0, hdg=math.pi / 2, length=10.0, kind="line")
    x, y, h = _end(g)
    assert (x, y, h) == pytest.approx((3.0, 8.0, math.pi / 2), abs=1e-12)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_quarter_arc_turns_ninety_degrees(sign: float) -> None:
    # radius 10 m, quarter circle: left turn ends at (10, 10), right turn at (10, -10)
    g = Geometry(0, 0.0, 0.0, 0.0, math.pi * 10 / 2, "arc", {"curvature": sign / 10})
    x, y, h = _end(g)
    assert (x, y, h) == pytest.approx((10.0, sign * 10.0, sign * math.pi / 2), abs=1e-9)
    mid = eval_geometry(g, np.array([g.length / 2]))
    # halfway point lies on the circle around (0, 10 * sign)
    assert math.hypot(mid[0][0], mid[1][0] - 10 * sign) == pytest.approx(10.0, abs=1e-9)


def test_clothoid_heading_and_position_match_fresnel() -> None:
    k, length = 0.05, 40.0
    g = Geometry(0, 1.0, 2.0, 0.0, length, "spiral", {"curvStart": 0.0, "curvEnd": k})
    x, y, h = _end(g)
    assert h == pytest.approx(k * length / 2, abs=1e-12)
    # theta(s) = a s^2 / 2 with a = k / L: x = sqrt(pi/a) C(s sqrt(a/pi)), y = sqrt(pi/a) S(...)
    a = k / length
    s_f, c_f = fresnel(length * math.sqrt(a / math.pi))
    scale = math.sqrt(math.pi / a)
    assert x == pytest.approx(1.0 + scale * c_f, abs=1e-9)
    assert y == pytest.approx(2.0 + scale * s_f, abs=1e-9)


def test_spiral_with_constant_curvature_equals_arc() -> None:
    arc = Geometry(0, 0.0, 0.0, 0.3, 25.0, "arc", {"curvature": -0.02})
    spiral = Geometry(0, 0.0, 0.0, 0.3, 25.0, "spiral", {"curvStart": -0.02, "curvEnd": -0.02})
    ds = np.linspace(0, 25, 11)
    for a, b in zip(eval_geometry(arc, ds), eval_geometry(spiral, ds), strict=True):
        np.testing.assert_allclose(a, b, atol=1e-9)


def test_spiral_from_nonzero_curvature_is_continuous_with_its_heading() -> None:
    g = Geometry(0, 0.0, 0.0, 0.0, 30.0, "spiral", {"curvStart": 0.02, "curvEnd": -0.04})
    ds = np.linspace(0, 30, 3001)
    x, y, h = eval_geometry(g, ds)
    step = np.hypot(np.diff(x), np.diff(y))
    np.testing.assert_allclose(step, 0.01, rtol=1e-6)  # unit-speed parametrisation
    chord_dir = np.arctan2(np.diff(y), np.diff(x))
    np.testing.assert_allclose(chord_dir, (h[1:] + h[:-1]) / 2, atol=1e-6)
    assert h[-1] == pytest.approx(0.02 * 30 + 0.5 * (-0.06 / 30) * 30**2, abs=1e-12)


def test_poly3_straight_diagonal_and_offset() -> None:
    # v = 1 + u: a 45 degree line starting 1 m to the left of (x, y)
    length = 10.0
    g = Geometry(0, 5.0, 5.0, 0.0, length, "poly3", {"a": 1.0, "b": 1.0, "c": 0.0, "d": 0.0})
    x0, y0, _ = eval_geometry(g, np.array([0.0]))
    assert (x0[0], y0[0]) == pytest.approx((5.0, 6.0))
    x, y, h = _end(g)
    r = length / math.sqrt(2)
    assert (x, y, h) == pytest.approx((5.0 + r, 6.0 + r, math.pi / 4), abs=1e-6)


def test_poly3_ds_is_arc_length_and_points_lie_on_the_cubic() -> None:
    g = Geometry(0, 0.0, 0.0, 0.0, 20.0, "poly3", {"a": 0.0, "b": 0.0, "c": 0.02, "d": -0.0005})
    ds = np.linspace(0, 20, 4001)
    x, y, _ = eval_geometry(g, ds)
    assert np.sum(np.hypot(np.diff(x), np.diff(y))) == pytest.approx(20.0, abs=1e-4)
    np.testing.assert_allclose(y, 0.02 * x**2 - 0.0005 * x**3, atol=1e-6)


def test_param_poly3_normalized_equals_scaled_arc_length() -> None:
    length = 12.0
    arc_len = {
        "aU": 0,
        "bU": 1,
        "cU": 0,
        "dU": 0,
        "aV": 0,
        "bV": 0,
        "cV": 0.03,
        "dV": -0.001,
        "pRange": "arcLength",
    }
    norm = {
        "aU": 0, "bU": length, "cU": 0, "dU": 0,
        "aV": 0, "bV": 0, "cV": 0.03 * length**2, "dV": -0.001 * length**3, "pRange": "normalized",
    }  # fmt: skip
    ga = Geometry(0, 1.0, 1.0, 0.7, length, "paramPoly3", arc_len)
    gn = Geometry(0, 1.0, 1.0, 0.7, length, "paramPoly3", norm)
    ds = np.linspace(0, length, 7)
    for a, b in zip(eval_geometry(ga, ds), eval_geometry(gn, ds), strict=True):
        np.testing.assert_allclose(a, b, atol=1e-9)
    # hand value at p = L: local (12, 0.03*144 - 0.001*1728) = (12, 2.592), rotated by 0.7 rad
    x, y, _ = _end(ga)
    u, v = 12.0, 2.592
    assert (x, y) == pytest.approx(
        (1 + u * math.cos(0.7) - v * math.sin(0.7), 1 + u * math.sin(0.7) + v * math.cos(0.7))
    )


def test_reference_line_picks_the_record_and_clamps() -> None:
    line = Geometry(0, 0.0, 0.0, 0.0, 10.0, "line")
    arc = Geometry(10, 10.0, 0.0, 0.0, math.pi * 5, "arc", {"curvature": 0.1})
    ref = ReferenceLine([line, arc])
    x, y, h = ref.evaluate(np.array([5.0, 10.0, 10 + math.pi * 5]))
    np.testing.assert_allclose(x, [5.0, 10.0, 20.0], atol=1e-9)
    np.testing.assert_allclose(y, [0.0, 0.0, 10.0], atol=1e-9)
    assert h[-1] == pytest.approx(math.pi / 2)


def test_piecewise_polynomials_and_section_end() -> None:
    polys = [Poly(0.0, 1.0, 0.5), Poly(4.0, 7.0, 0.0, 0.25)]  # jumps from 3 to 7 at s = 4
    v = eval_polys(polys, np.array([0.0, 2.0, 4.0, 6.0]))
    np.testing.assert_allclose(v, [1.0, 2.0, 7.0, 8.0])
    # at a record boundary that is a section end, `below` keeps the previous record
    assert eval_polys(polys, np.array([4.0]), below=4.0)[0] == pytest.approx(3.0)
    assert eval_polys(polys, np.array([4.0]), below=4.0 + 1e-6)[0] == pytest.approx(7.0)
    assert eval_polys([Poly(0, 1.0)], np.array([4.0]), below=4.0)[0] == 1.0
    # section-relative records (lane widths)
    np.testing.assert_allclose(
        eval_polys([Poly(0.0, 2.0, 0.1)], np.array([10.0, 15.0]), origin=10.0), [2.0, 2.5]
    )
