"""zmap.cam.drop_cutter against analytic CL heights, the brute-force reference and a B-rep."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from tests.conftest import DATA
from zmap import ZMap
from zmap.cam import drop_cutter
from zmap.cam._reference import drop_cutter_reference
from zmap.sim.tools import Cutter, parse_tool_spec


def _env(c, d):
    return c.lower_envelope(np.asarray(d, dtype=float))


@pytest.mark.parametrize("spec", ["ball:6", "flat:6", "bull:6:1"])
def test_tilted_plane_exact(spec):
    c = parse_tool_spec(spec)
    a = 0.3
    plane = ZMap.from_function(lambda x, y: a * x + 1.0, (-20, -20, 20, 20), 0.2)
    rng = np.random.default_rng(0)
    x, y = rng.uniform(-10, 10, 40), rng.uniform(-10, 10, 40)
    cl = drop_cutter(plane, c, x, y)
    R, rc = c.radius, c.corner_radius
    # contact on the torus / ball side facing uphill, or on the rim for a flat end
    if c.kind == "flat":
        want = a * (x + R) + 1.0
    else:
        n = np.hypot(a, 1.0)
        want = a * x + 1.0 + a * (R - rc) + rc * (n - 1.0)
    assert np.abs(cl - want).max() < 1e-5  # the sub-sample paraboloid: ~1e-6 at pitch 0.2


@pytest.mark.parametrize("spec", ["ball:6", "flat:4", "bull:6:1.5"])
def test_step_wall_edge_exact(spec):
    c = parse_tool_spec(spec)
    wall = lambda x, y: np.where(x > 0.013, 2.0, 0.0)  # noqa: E731  a vertical wall at x = 0.013
    x = np.linspace(-c.radius - 0.5, 0.5, 120)
    cl = drop_cutter(wall, c, x, 0.3 + 0 * x, pitch=0.1)
    d = 0.013 - x
    want = np.where(d <= 0, 2.0, np.where(d <= c.radius, 2.0 - np.nan_to_num(_env(c, np.clip(d, 0, c.radius)), nan=9), 0.0))
    want = np.maximum(want, 0.0)
    assert np.abs(cl - want).max() < 1e-5


def test_sphere_offset_surface():
    Rs = 40.0
    sph = ZMap.from_function(lambda x, y: np.sqrt(np.clip(Rs ** 2 - x * x - y * y, 0, None)), (-25, -25, 25, 25), 0.25)
    c = parse_tool_spec("ball:6")
    rng = np.random.default_rng(1)
    r = rng.uniform(0, 15, 100)
    t = rng.uniform(0, 2 * np.pi, 100)
    x, y = r * np.cos(t), r * np.sin(t)
    cl = drop_cutter(sph, c, x, y)
    want = np.sqrt((Rs + 3) ** 2 - r * r) - 3
    assert np.abs(cl - want).max() < 5e-5  # smooth contacts: the sub-sample paraboloid, ~1e-5


@settings(max_examples=6, deadline=None, derandomize=True)
@given(seed=st.integers(0, 1000), spec=st.sampled_from(["ball:4", "flat:4", "bull:5:1"]))
def test_agrees_with_brute_force_reference(seed, spec):
    rng = np.random.default_rng(seed)
    kx, ky, h = rng.uniform(0.2, 1.2, 3)
    xw = rng.uniform(-2, 2)

    def f(x, y):
        return 0.4 * np.sin(kx * x) * np.cos(ky * y) + np.where(x > xw, h, 0.0)

    c = parse_tool_spec(spec)
    x, y = rng.uniform(-4, 4, 6), rng.uniform(-4, 4, 6)
    got = drop_cutter(f, c, x, y, pitch=0.1)
    ref = drop_cutter_reference(f, c, x, y, h=0.02, levels=3)
    # ours is an exact contact (never above the true CL); the reference is a lattice search
    assert np.abs(got - ref).max() < 1e-4


def test_no_surface_is_nan_and_scalar_shape():
    hole = lambda x, y: np.where(x * x + y * y < 100, np.nan, 1.0)  # noqa: E731
    assert np.isnan(drop_cutter(hole, "ball:4", 0.0, 0.0, pitch=0.2))
    v = drop_cutter(hole, "ball:4", 9.5, 0.0, pitch=0.2)
    assert isinstance(v, float) and v == pytest.approx(1.0 - (2.0 - np.sqrt(4 - 0.25)), abs=1e-6)
    out = drop_cutter(hole, "ball:4", np.zeros((2, 3)) + 20, np.zeros((2, 3)), pitch=0.5)
    assert out.shape == (2, 3)


def test_bad_input():
    plane = ZMap.from_function(lambda x, y: 0 * x, (0, 0, 5, 5), 0.5)
    with pytest.raises(ValueError, match="finite"):
        drop_cutter(plane, "ball:2", np.nan, 1.0)
    with pytest.raises(ValueError, match="pitch"):
        drop_cutter(plane, "ball:2", 1.0, 1.0, pitch=-1)
    with pytest.raises(ValueError, match="cutter"):
        drop_cutter(plane, 3, 1.0, 1.0)
    with pytest.raises(ValueError, match="model"):
        drop_cutter("nope", "ball:2", 1.0, 1.0)


@pytest.fixture(scope="module")
def boss():
    import cad_io

    return cad_io.read_step(DATA / "boss.step")


def test_brep_walls_edges_and_corners(boss):
    # boss.step: plate top z = 10; rectangular boss x -30..0, y -5..15, top 22; round boss
    # R 8 at (22, -12), top 16; all edges sharp
    c = Cutter("ball", 6.0)
    env = lambda d: 3 - np.sqrt(9 - d * d)  # noqa: E731
    rng = np.random.default_rng(1)
    d = rng.uniform(0.05, 2.95, 12)
    wall_x, wall_y = d, rng.uniform(-4, 14, 12)                      # beside the straight wall x = 0
    a = rng.uniform(0.05, np.pi / 2 - 0.05, 12)
    corner_x, corner_y = d * np.cos(a), 15 + d * np.sin(a)           # beside the corner (0, 15)
    flat_x, flat_y = rng.uniform(5, 15, 12), rng.uniform(15, 25, 12)  # on the plate, far from walls
    top_x, top_y = rng.uniform(-15, -5, 12), rng.uniform(0, 10, 12)  # on the boss top
    groups = [(wall_x, wall_y, 22 - env(d)), (corner_x, corner_y, 22 - env(d)),
              (flat_x, flat_y, np.full(12, 10.0)), (top_x, top_y, np.full(12, 22.0))]
    for gx, gy, want in groups:  # one call per group: each samples only its own window
        got = drop_cutter(boss, c, gx, gy)
        assert np.abs(got - want).max() < 1e-4
    # round boss: a circular top edge; the B-rep heights count points within the sampler's
    # trim slack (5e-4 mm) of a trim loop as inside, which lifts the contact by at most
    # that slack times the envelope's slope there
    t = rng.uniform(0, 2 * np.pi, 12)
    rx, ry = 22 + (8 + d) * np.cos(t), -12 + (8 + d) * np.sin(t)
    got = drop_cutter(boss, c, rx, ry)
    want = 16 - env(d)
    slope = d / np.sqrt(9 - d * d)
    assert (got - want >= -1e-4).all()
    assert (got - want <= 1e-4 + 6e-4 * slope).all()
