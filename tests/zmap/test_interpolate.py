import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zmap import ZMap
from tests.reference.interpolate import bezier_reference, bilinear_reference
from zmap.errors import OutOfDomainError
from zmap.interpolate import SCHEMES, bezier, bilinear, evaluate

ALL = list(SCHEMES)


def plane(x, y):
    return 0.3 * x - 0.7 * y + 12.0


@pytest.mark.parametrize("scheme", ALL)
@pytest.mark.parametrize("boundary", ["dummy", "one-sided"])
def test_tilted_plane_reproduced_everywhere(scheme, boundary):
    zm = ZMap.from_function(plane, (-3, -2, 5, 6), 0.5, 0.8)
    rng = np.random.default_rng(1)
    x = rng.uniform(-3, 5, 20000)
    y = rng.uniform(-2, zm.y1, 20000)
    if scheme == "bilinear":
        h = bilinear(zm, x, y)
    else:
        h = bezier(zm, x, y, tangent={"bezier": "circle"}.get(scheme, scheme.split("-")[-1]), boundary=boundary)
    assert np.abs(h - plane(x, y)).max() <= 1e-12


@pytest.mark.parametrize("scheme", ALL)
def test_rotated_frame_plane(scheme):
    ang, ox, oy = 0.4, 3.0, -1.0
    c, s = math.cos(ang), math.sin(ang)
    # Heights of the world plane at the rotated grid's points.
    zm = ZMap(0.0, 0.0, 0.25, 0.1, np.zeros((9, 12)), angle=ang, origin=(ox, oy))
    wx, wy = zm.grid_points()
    zm.z[:] = plane(wx, wy)
    lx = np.random.default_rng(2).uniform(0, zm.x1, 500)
    ly = np.random.default_rng(3).uniform(0, zm.y1, 500)
    x, y = ox + c * lx - s * ly, oy + s * lx + c * ly
    assert np.abs(evaluate(zm, x, y, scheme=scheme) - plane(x, y)).max() <= 1e-12


@pytest.mark.parametrize("scheme", ALL)
def test_grid_points_are_exact(scheme):
    zm = ZMap.from_function(lambda x, y: np.sin(x) * np.cos(y), (0, 0, 3, 3), 0.25)
    X, Y = zm.grid_points()
    np.testing.assert_allclose(evaluate(zm, X, Y, scheme=scheme), zm.z, rtol=0, atol=1e-14)


def test_quartic_reproduces_separable_cubics_in_the_interior():
    f = lambda x, y: 0.02 * x**3 - 0.3 * x**2 + x - 0.01 * y**3 + 0.2 * y**2  # noqa: E731
    zm = ZMap.from_function(f, (-6, -6, 6, 6), 0.5)
    rng = np.random.default_rng(4)
    x, y = rng.uniform(-5, 5, 5000), rng.uniform(-5, 5, 5000)
    np.testing.assert_allclose(bezier(zm, x, y, tangent="quartic"), f(x, y), rtol=0, atol=1e-11)


small_maps = st.builds(
    lambda nx, ny, dx, dy, seed: ZMap(-1.0, 2.0, dx, dy, np.random.default_rng(seed).normal(0, 2, (nx, ny))),
    st.integers(2, 7), st.integers(2, 7), st.floats(0.1, 3.0), st.floats(0.1, 3.0), st.integers(0, 2**32 - 1))


@settings(max_examples=60, deadline=None)
@given(zm=small_maps, data=st.data())
def test_kernels_agree_with_reference(zm, data):
    u = data.draw(st.lists(st.floats(0, 1), min_size=5, max_size=5))
    v = data.draw(st.lists(st.floats(0, 1), min_size=5, max_size=5))
    x = zm.x0 + np.array(u) * (zm.x1 - zm.x0)
    y = zm.y0 + np.array(v) * (zm.y1 - zm.y0)
    got_b = bezier(zm, x, y)
    got_l = bilinear(zm, x, y)
    for k in range(5):
        ref = bezier_reference(zm, x[k], y[k])
        assert got_b[k] == pytest.approx(ref, rel=1e-9, abs=1e-9 * (1 + np.abs(zm.z).max()))
        assert got_l[k] == pytest.approx(bilinear_reference(zm, x[k], y[k]), rel=1e-12, abs=1e-12)


@pytest.mark.parametrize("scheme", ALL)
def test_nan_policy(scheme):
    zm = ZMap.from_function(lambda x, y: x + y, (0, 0, 6, 6), 1.0)
    zm.z[0, 0] = np.nan  # a corner of cell (0, 0) and an outer stencil point of cells nearby
    q = np.array([[0.5, 0.5], [1.5, 1.5], [2.5, 0.5], [-0.1, 3], [3, 6.1], [np.nan, 1], [1, np.inf], [6, 6]])
    h = evaluate(zm, q[:, 0], q[:, 1], scheme=scheme)
    assert math.isnan(h[0])  # corner missing
    assert h[1] == pytest.approx(3.0, abs=1e-12)  # stencil point missing: one-sided fallback, plane kept
    assert h[2] == pytest.approx(3.0, abs=1e-12)
    assert np.isnan(h[3:7]).all()  # outside, NaN or infinite coordinates
    assert h[7] == pytest.approx(12.0)  # the far corner of the domain is inside
    with pytest.raises(OutOfDomainError, match=r"point 0 .*missing corner"):
        evaluate(zm, q[:, 0], q[:, 1], scheme=scheme, strict=True)
    with pytest.raises(OutOfDomainError, match="outside the map"):
        evaluate(zm, [1.0, -1.0], [1.0, 1.0], scheme=scheme, strict=True)
    with pytest.raises(OutOfDomainError, match="non-finite"):
        evaluate(zm, [np.nan], [1.0], scheme=scheme, strict=True)


def test_missing_stencil_points_fall_back_to_complete_stencils():
    f = lambda x, y: 0.05 * x * x + 0.02 * y * y  # noqa: E731
    zm = ZMap.from_function(f, (0, 0, 10, 10), 1.0)
    zm.z[3, 5] = np.nan
    # Cell (4, 5) has all corners; its stencil misses (3, 5). Result finite and close.
    h = bezier(zm, 4.5, 5.5, tangent="circle")
    assert math.isfinite(h) and abs(h - f(4.5, 5.5)) < 0.01
    # Cells around a missing height isolate it: the 4 cells touching (3, 5) give NaN.
    assert math.isnan(bezier(zm, 3.5, 5.5)) and math.isnan(bezier(zm, 2.5, 4.5))


def test_shapes_scalars_and_broadcasting():
    zm = ZMap.from_function(plane, (0, 0, 4, 4), 1.0)
    assert isinstance(bezier(zm, 1.0, 2.0), float)
    assert bezier(zm, np.zeros((3, 1)), np.zeros((1, 4))).shape == (3, 4)
    with pytest.raises(ValueError, match="broadcast"):
        bilinear(zm, np.zeros(3), np.zeros(4))


def test_bad_options_name_the_value():
    zm = ZMap.from_function(plane, (0, 0, 4, 4), 1.0)
    with pytest.raises(ValueError, match=r"tangent='circel' is not one of 'circle', 'central', 'quartic'"):
        bezier(zm, 1, 1, tangent="circel")
    with pytest.raises(ValueError, match="boundary='x'"):
        bezier(zm, 1, 1, boundary="x")
    with pytest.raises(ValueError, match="scheme='cubic'"):
        evaluate(zm, 1, 1, scheme="cubic")
    with pytest.raises(TypeError, match="ZMap"):
        bezier(np.zeros((3, 3)), 1, 1)


def test_one_sided_circle_tangent_next_to_a_hole_does_not_overshoot():
    # Heights from trj8_b1-ec-214.stp beside an empty region: the circle through the three
    # steep heights 4.8, 17.7, 23.1 has a near-vertical tangent at 4.8, and the Bezier cubic
    # used to reach 1056 mm inside a cell whose corners lie between 4.8 and 23.5.
    z = np.array([[np.nan, np.nan, 10.07316167, 22.3024254],
                  [np.nan, 4.79900634, 17.74701516, 23.0983555],
                  [np.nan, 12.80438684, 22.88879471, 23.52141674],
                  [7.73988094, 19.23411314, 23.51642051, 23.83803887]])
    zm = ZMap(0.0, 0.0, 0.5, 0.5, z)
    g = np.linspace(0.0, 1.0, 41)
    X, Y = np.meshgrid(0.5 + 0.5 * g, 0.5 + 0.5 * g, indexing="ij")  # cell (1, 1)
    for tangent in ("circle", "central", "quartic"):
        h = bezier(zm, X, Y, tangent=tangent)
        assert np.isfinite(h).all()
        assert h.min() >= 4.79900634 - 2.0 and h.max() <= 22.88879471 + 2.0, tangent
