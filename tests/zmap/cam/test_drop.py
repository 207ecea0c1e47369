"""zmap.cam.drop_cutter against analytic CL heights, the brute-force reference and a B-rep."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from tests.conftest import DATA, STEP_DATA
from zmap import ZMap
from zmap.cam import drop_cutter
from tests.reference.cam import drop_cutter_reference
from tests.zmap.cam.brute import brute_zmap as _brute_zmap
from zmap.sim.tools import Cutter, parse_tool_spec

# one xdist worker compiles this family's numba kernels once (tests/conftest.py)
pytestmark = pytest.mark.xdist_group("cam")


def _env(c, d):
    return c.lower_envelope(np.asarray(d, dtype=float))


@pytest.mark.parametrize("spec", ["ball:6", "flat:6", "bull:6:1"])
@pytest.mark.slow
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


def _wall_cl(c, x, xw):
    """The analytic CL beside a vertical wall at x = xw, 2 mm high (floor 0)."""
    d = xw - x
    inside = np.clip(d, 0, c.radius)
    want = np.where(d <= 0, 2.0, np.where(d <= c.radius, 2.0 - np.nan_to_num(_env(c, inside), nan=9), 0.0))
    return np.maximum(want, 0.0)


@pytest.mark.parametrize("spec", ["ball:6", "flat:4", "bull:6:1.5"])
@pytest.mark.slow
def test_step_wall_never_below_and_within_a_sample(spec):
    # a design known only by its heights is sampled: never below the true CL; above it by at
    # most what the wall moved toward the tool by one pitch gives
    c = parse_tool_spec(spec)
    wall = lambda x, y: np.where(x > 0.013, 2.0, 0.0)  # noqa: E731  a vertical wall at x = 0.013
    x = np.linspace(-c.radius - 0.5, 0.5, 120)
    cl = drop_cutter(wall, c, x, 0.3 + 0 * x, pitch=0.1)
    want = _wall_cl(c, x, 0.013)
    assert (cl >= want - 1e-9).all()
    assert (cl <= _wall_cl(c, x, 0.013 - 0.1) + 5e-5).all()  # a few eps (1e-5)


@pytest.mark.parametrize("spec", ["ball:6", "flat:4", "bull:6:1.5"])
@pytest.mark.slow
def test_step_wall_on_a_zmap_exact(spec):
    # the same wall as a z-map: its own Bezier surface is the design, dropped on exactly
    c = parse_tool_spec(spec)
    zm = ZMap.from_function(lambda x, y: np.where(x > 0.013, 2.0, 0.0), (-10, -5, 5, 5), 0.25)
    x = np.linspace(-c.radius - 0.5, 0.5, 60)
    y = 0.3 + 0 * x
    cl = drop_cutter(zm, c, x, y)
    ref = _brute_zmap(zm, c, x, y)
    assert (cl >= ref - 1e-9).all()       # the brute force samples real points: never above ours
    assert (cl - ref).max() < 5e-3        # its lattice (0.01 mm) misses the patch's top by little


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
    # the z-map's Bezier surface is within ~1e-5 of the sphere; the drop on it within 1e-5
    assert np.abs(cl - want).max() < 5e-5


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
    # the reference is a lattice search (real points: never above the true CL); ours never below
    assert (got >= ref - 1e-4).all()
    # away from the step the sampled design is smooth and ours exact to the reference's error
    far = np.abs(x - xw) > c.radius + 0.2
    assert np.abs(got - ref)[far].max(initial=0.0) < 1e-4


def test_no_surface_is_nan_and_scalar_shape():
    hole = lambda x, y: np.where(x * x + y * y < 100, np.nan, 1.0)  # noqa: E731
    assert np.isnan(drop_cutter(hole, "ball:4", 0.0, 0.0, pitch=0.2))
    v = drop_cutter(hole, "ball:4", 9.5, 0.0, pitch=0.2)
    want = 1.0 - (2.0 - np.sqrt(4 - 0.25))  # the ball on the hole's edge at r = 10
    # sampled: never below; a cell on the edge counts as whole (0.2 mm, up to 0.3 across)
    assert isinstance(v, float) and want - 1e-9 <= v <= 1.0 - (2.0 - np.sqrt(4 - 0.2 ** 2)) + 1e-9
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
    with pytest.raises(ValueError, match="must be a ZMap, a TiledZMap, a PrecisionModel, a STEP part"):
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
    # a part is sampled (exact heights every 0.05 mm here): never below the true CL; beside a
    # wall above it by at most the wall moved toward the tool by one pitch (0.1 mm)
    for k, (gx, gy, want) in enumerate(groups):  # one call per group: each samples its own window
        got = drop_cutter(boss, c, gx, gy, pitch=0.1)
        assert (got - want >= -1e-4).all()
        if k < 2:
            assert (got - want <= env(d) - env(np.clip(d - 0.1, 0, 3)) + 1e-4).all()
        else:
            assert np.abs(got - want).max() < 1e-4
    # round boss: a circular top edge, which crosses the sampled cells on the diagonal too:
    # above the true CL by at most the edge moved toward the tool by a cell's diagonal
    t = rng.uniform(0, 2 * np.pi, 12)
    rx, ry = 22 + (8 + d) * np.cos(t), -12 + (8 + d) * np.sin(t)
    got = drop_cutter(boss, c, rx, ry, pitch=0.1)
    want = 16 - env(d)
    assert (got - want >= -1e-4).all()
    assert (got - want <= env(d) - env(np.clip(d - 0.1 * np.sqrt(2), 0, 3)) + 1e-4).all()


@settings(max_examples=8, deadline=None, derandomize=True)
@given(seed=st.integers(0, 10_000), spec=st.sampled_from(["ball:6", "flat:4", "bull:5:1"]))
@pytest.mark.slow
def test_zmap_drop_never_below_an_independent_brute_force(seed, spec):
    # random z-maps with steps, bumps and holes (missing heights): every node under the cutter
    # and the surface between them, sampled by the brute force, stays below the CL
    rng = np.random.default_rng(seed)
    nx, ny = 40, 36
    X, Y = np.meshgrid(np.arange(nx) * 0.5, np.arange(ny) * 0.5, indexing="ij")
    z = (rng.uniform(0.1, 0.8) * np.sin(X / rng.uniform(1, 4)) * np.cos(Y / rng.uniform(1, 4))
         + np.where(X > rng.uniform(4, 15), rng.uniform(0.5, 3), 0.0)
         + np.where((X - 10) ** 2 + (Y - 9) ** 2 < rng.uniform(1, 16), rng.uniform(-2, 2), 0.0))
    hole = (np.abs(X - rng.uniform(3, 16)) < 1.2) & (np.abs(Y - rng.uniform(3, 14)) < 1.6)
    z[hole] = np.nan
    zm = ZMap(0.0, 0.0, 0.5, 0.5, z)
    c = parse_tool_spec(spec)
    x, y = rng.uniform(-1, 20.5, 25), rng.uniform(-1, 18.5, 25)
    cl = drop_cutter(zm, c, x, y)
    ref = _brute_zmap(zm, c, x, y)
    assert np.array_equal(np.isnan(cl), np.isnan(ref))
    ok = np.isfinite(ref)
    assert (cl[ok] >= ref[ok] - 1e-9).all()
    # and not far above: the brute force's lattice (0.01 mm) misses the top of a steep patch
    # beside a step by up to its slope times half the spacing
    assert (cl[ok] - ref[ok]).max(initial=0.0) < 0.05


@pytest.fixture(scope="module")
def cornetta():
    cad_io = pytest.importorskip("cad_io")
    return cad_io.read_step(STEP_DATA / "bug27693_cornetta-step.stp")


@pytest.mark.slow
def test_step_design_never_below_its_exact_heights_where_a_fillet_meets_a_plane(cornetta):
    # on the cornetta die a fillet meets a plane at x = -55.34 (the curvature jumps): a cubic
    # through samples 0.5 mm apart errs both ways between them there, and a margin from the
    # samples' rise alone let the drop fall 7e-4 mm under the part at (-52.2, 11.5), on the
    # grid the whole-die program sampled (its origin: the part's bounds less 5 mm)
    from cad_io.sampler import height_function

    from zmap.cam.drop import bounding_surface

    from tests.zmap.cam.brute import brute_heights

    c = parse_tool_spec("ball:6")
    bounding_surface(cornetta, (-60.0000001, 4.9999999, -45.0000001, 17.9999999), pitch=0.5)
    x = np.r_[-52.2, np.linspace(-54.6, -51.0, 9)]
    y = np.r_[11.5, np.full(9, 10.8)]
    got = drop_cutter(cornetta, c, x, y, pitch=0.5)
    ref = brute_heights(height_function(cornetta), c, x, y)
    assert (got >= ref - 1e-4).all(), (got - ref).min()
    assert (got - ref).max() < 0.05
