"""The drop-cutter's numba model evaluation and refinement (zmap.cam._model_eval).

The kernel's heights are held to ``PrecisionModel.height`` on real EZ models (a layout change
in zmap.refine shows up here), and the CL heights to the brute-force reference on models
with walls: ours is an upper bound, so it may exceed a lattice search but must never be
below it by more than 1e-4 mm (below would be a missed maximum: a gouge).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from tests.conftest import DATA, STEP_DATA
from zmap import ZMap
from zmap.cam import drop_cutter
from zmap.cam import _model_eval as ME
from tests.reference.cam import drop_cutter_reference
from zmap.model import PrecisionModel
from zmap.sim.tools import parse_tool_spec

# one xdist worker compiles this family's numba kernels once (tests/conftest.py)
pytestmark = pytest.mark.xdist_group("cam")


def _kernel_heights(model, x, y):
    M = ME.pack_model(model)
    x = np.ascontiguousarray(x, dtype=np.float64)
    y = np.ascontiguousarray(y, dtype=np.float64)
    out = np.empty(x.size)
    ME.threaded(ME.heights, x.size, M, x, y, out, chunk=1000)
    return out


@pytest.fixture(scope="module")
def boss_ez():
    import cad_io
    from cad_io.refine import RefineOptions, refine_models

    part = cad_io.read_step(DATA / "boss.step")
    b = part.bbox
    base = cad_io.sample(part, 1.0, bounds=(b[0] - 2, b[1] - 2, b[3] + 2, b[4] + 2))
    return refine_models(part, base, RefineOptions(0.01, ("ez",)))["ez"][0]


@pytest.mark.slow
def test_kernel_heights_are_the_models_on_a_real_ez_model(boss_ez):
    m = boss_ez
    assert m.ez is not None and m.ez.n_patches > 0  # the patch path is exercised too
    rng = np.random.default_rng(0)
    b = m.base
    x = rng.uniform(b.x0 - 1, b.x0 + (b.nx - 1) * b.dx + 1, 50_000)
    y = rng.uniform(b.y0 - 1, b.y0 + (b.ny - 1) * b.dy + 1, 50_000)
    # points in the patched cells and in every EZ cell
    cells = np.flatnonzero(m.ez.cell_mask().ravel())
    ci, cj = np.divmod(np.r_[m.ez.patches.cells, cells], b.ny - 1)
    u, v = rng.uniform(0, 1, (2, ci.size, 40))
    x = np.r_[x, (b.x0 + (ci[:, None] + u) * b.dx).ravel()]
    y = np.r_[y, (b.y0 + (cj[:, None] + v) * b.dy).ravel()]
    got = _kernel_heights(m, x, y)
    want = m.height(x, y)
    assert (m.source(x, y) == 3).sum() > 10_000
    np.testing.assert_array_equal(got, want)


def test_kernel_heights_pick_the_deepest_cz_map():
    f = lambda x, y: 0.2 * x + np.sin(y) + np.where(x > 1.3 * y + 0.4, 1.5, 0.0)  # noqa: E731
    base = ZMap.from_function(f, (-6, -6, 6, 6), 0.5)
    cz1 = ZMap.from_function(f, (-3, -2, 3, 2), 0.1, angle=math.radians(30), origin=(0.5, 0.0))
    cz2 = ZMap.from_function(f, (-2, -3, 2, 1), 0.1, angle=math.radians(-50), origin=(-1.0, 1.0))
    m = PrecisionModel(base, [cz1, cz2])
    rng = np.random.default_rng(1)
    x, y = rng.uniform(-7, 7, (2, 20_000))
    assert {0, 1, 2} <= set(np.unique(m.source(x, y)).tolist())
    np.testing.assert_array_equal(_kernel_heights(m, x, y), m.height(x, y))


def test_zmap_model_is_its_bezier():
    from zmap.interpolate import bezier

    z = ZMap.from_function(lambda x, y: np.cos(x) * y, (0, 0, 5, 4), 0.25)
    rng = np.random.default_rng(2)
    x, y = rng.uniform(-0.5, 5.5, (2, 5000))
    np.testing.assert_array_equal(_kernel_heights(z, x, y), bezier(z, x, y))


def test_kernel_bezier_options_are_not_compile_time_constants():
    # pack_model hands the slopes' kernel the Bezier options as run-time ints: constants would
    # be typed as literals, and numba would compile _slope and its callees once more for them
    # (seconds of a cold compile) instead of sharing the signature PrecisionModel.height compiles
    from numba import types

    from zmap import _interp_kernels as IK

    z = ZMap.from_function(lambda x, y: x * y, (0, 0, 3, 3), 0.5)
    ME.pack_model(z)
    x = np.array([1.2, 2.7])
    np.testing.assert_array_equal(_kernel_heights(z, x, x), PrecisionModel(z).height(x, x))
    sigs = IK.slope_tables.signatures
    assert sigs and not any(isinstance(a, types.Literal) for sig in sigs for a in sig), sigs


def _wall_model(seed):
    rng = np.random.default_rng(seed)
    cx, cy, rr = rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(1.5, 3.0)
    h, a, k = rng.uniform(0.5, 4.0), rng.uniform(-0.3, 0.3), rng.uniform(0.3, 1.0)

    def f(x, y):  # a round boss with a sloped, wavy top on a sloped floor
        top = np.where(np.hypot(x - cx, y - cy) < rr, h + 0.2 * np.sin(k * x + y), 0.0)
        return a * x + top

    base = ZMap.from_function(f, (-8, -8, 8, 8), 0.5)
    from zmap.refine.ez import build_ez

    return PrecisionModel(base, ez=build_ez(base, f, tol=0.01)), (cx, cy, rr)


@settings(max_examples=5, deadline=None, derandomize=True)
@given(seed=st.integers(0, 10_000), spec=st.sampled_from(["ball:6", "ball:4", "bull:6:1", "flat:4"]))
@pytest.mark.slow
def test_never_below_the_brute_force_on_walls(seed, spec):
    model, (cx, cy, rr) = _wall_model(seed)
    c = parse_tool_spec(spec)
    rng = np.random.default_rng(seed + 1)
    # axes near the wall (its top edge is the contact) and anywhere
    t = rng.uniform(0, 2 * np.pi, 4)
    d = rr + rng.uniform(-0.5, 0.8 * c.radius, 4)
    x = np.r_[cx + d * np.cos(t), rng.uniform(-4, 4, 2)]
    y = np.r_[cy + d * np.sin(t), rng.uniform(-4, 4, 2)]
    got, gx, gy, _ = drop_cutter(model, c, x, y, pitch=0.1, return_contact=True)
    ref = drop_cutter_reference(model.height, c, x, y, h=0.02, levels=3)
    # the reference is a lattice search over real points: never above the true CL; ours never
    # below it (the model is sampled every 0.025 mm, walls bounded on their safe side)
    assert np.all(got >= ref - 1e-4), (got - ref).min()
    d = np.hypot(gx - x, gy - y)
    assert np.all(d <= c.radius * (1 + 1e-12))
    # off the wall (the disk clear of the boss's edge by a pitch) ours is the reference's
    far = np.abs(np.hypot(x - cx, y - cy) - rr) > c.radius + 0.2
    assert np.all(np.abs(got - ref)[far] < 1e-4)


def test_discrete_drop_is_never_above_the_certified_one():
    model, _ = _wall_model(7)
    rng = np.random.default_rng(3)
    x, y = rng.uniform(-7, 7, (2, 30))
    a = drop_cutter(model, "ball:4", x, y, pitch=0.1)
    b = drop_cutter(model, "ball:4", x, y, pitch=0.1, refine=False)
    assert np.all(a >= b - 1e-9)
    with pytest.raises(ValueError, match="eps"):
        drop_cutter(model, "ball:4", x, y, eps=0)


# Off-axis points of a 120 x 120 grid over the cornetta window of bench/verify.py where the
# compass search alone stopped below the brute force (by 2.1e-3 and 2.2e-4 mm at (20, 42) and
# (20, 76): a wall's top whose contact wiggles along it, near the rim), and their neighbours.
_GRID_POINTS = [(30, 41), (66, 39), (17, 72), (50, 54), (20, 42), (100, 42), (60, 40), (26, 79), (39, 78),
                (16, 49), (20, 76), (90, 79), (17, 61), (91, 79), (19, 64), (47, 57)]


@pytest.mark.slow
def test_cornetta_wall_tops_against_the_brute_force():
    import cad_io
    from cad_io.refine import RefineOptions, refine_models

    W = (-45.0, -25.0, 5.0, 25.0)
    part = cad_io.read_step(STEP_DATA / "bug27693_cornetta-step.stp")
    base = cad_io.sample(part, 0.5, bounds=(W[0] - 5, W[1] - 5, W[2] + 5, W[3] + 5))
    model = refine_models(part, base, RefineOptions(0.01, ("ez",)))["ez"][0]
    xs, ys = np.linspace(W[0], W[2], 120), np.linspace(W[1], W[3], 120)
    x = np.array([xs[i] for i, _ in _GRID_POINTS])
    y = np.array([ys[j] for _, j in _GRID_POINTS])
    ball = parse_tool_spec("ball:6")
    got = drop_cutter(model, ball, x, y, pitch=0.1)
    ref = drop_cutter_reference(model.height, ball, x, y, h=0.005, levels=3)
    assert np.all(got >= ref - 1e-4), np.round(got - ref, 6)
