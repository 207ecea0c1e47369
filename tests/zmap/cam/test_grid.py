"""The tensor-grid discrete drop (max-plus convolution, zmap.cam._grid_kernels) against the
brute-force max over the same samples, and drop_cutter on grids against scattered points."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zmap import ZMap
from zmap.cam import drop_cutter
from zmap.cam._grid_kernels import drop_grid
from zmap.sim.tools import parse_tool_spec

# one xdist worker compiles this family's numba kernels once (tests/conftest.py)
pytestmark = pytest.mark.xdist_group("cam")


def _brute(Z, dx, dy, c, qx, qy):
    """max over the finite samples with |sample - axis| <= R of z - envelope (-inf: none)."""
    nx, ny = Z.shape
    X = dx * np.arange(nx)[:, None] + 0 * Z
    Y = dy * np.arange(ny)[None, :] + 0 * Z
    out = np.full((qx.size, qy.size), -np.inf)
    for a in range(qx.size):
        for b in range(qy.size):
            ex, ey = X - qx[a], Y - qy[b]
            m = (ex * ex + ey * ey <= c.radius ** 2) & np.isfinite(Z)
            if m.any():
                out[a, b] = np.max(Z[m] - c.lower_envelope(np.minimum(np.hypot(ex[m], ey[m]), c.radius)))
    return out


@settings(max_examples=40, deadline=None, derandomize=True)
@given(seed=st.integers(0, 10_000), kind=st.sampled_from(["ball", "flat", "bull"]),
       holes=st.booleans(), ties=st.booleans())
@pytest.mark.slow
def test_grid_drop_is_the_max_over_the_samples(seed, kind, holes, ties):
    rng = np.random.default_rng(seed)
    R = rng.uniform(0.3, 2.5)
    spec = {"ball": f"ball:{2 * R}", "flat": f"flat:{2 * R}", "bull": f"bull:{2 * R}:{rng.uniform(0.05, 0.95) * R}"}
    c = parse_tool_spec(spec[kind])
    nx, ny = rng.integers(2, 30, 2)
    dx, dy = rng.uniform(0.05, 0.6, 2)
    Z = rng.normal(size=(nx, ny)) * rng.uniform(0.01, 3.0)
    if ties:
        Z = np.round(Z)  # plateaus: equal copies side by side
    if holes:
        Z[rng.random(Z.shape) < 0.25] = np.nan
    qx = rng.uniform(-2, nx * dx + 2, 6)
    qy = np.sort(rng.uniform(-2, ny * dy + 2, 8))
    if seed % 3 == 0:  # axes on the samples' lattice: samples exactly on the rim
        qx = dx * rng.integers(0, nx, 6).astype(float)
        qy = np.sort(dy * rng.integers(0, ny, 8).astype(float))
    out = np.empty((6, 8))
    oi = np.empty((6, 8), dtype=np.int64)
    oj = np.empty((6, 8), dtype=np.int64)
    drop_grid(Z, 0.0, 0.0, dx, dy, c.code, c.radius, c.corner_radius, qx, qy, out, oi, oj)
    ref = _brute(Z, dx, dy, c, qx, qy)
    fin = np.isfinite(ref)
    assert np.array_equal(np.isfinite(out), fin)
    assert np.array_equal(oi >= 0, fin)
    if fin.any():
        assert np.abs(out[fin] - ref[fin]).max() < 1e-9
        # the sample named is the one whose contact it is
        a, b = np.nonzero(fin)
        i, j = oi[a, b], oj[a, b]
        d = np.hypot(dx * i - qx[a], dy * j - qy[b])
        assert np.all(d <= c.radius * (1 + 1e-12))
        assert np.abs(Z[i, j] - c.lower_envelope(np.minimum(d, c.radius)) - out[a, b]).max() < 1e-9


@pytest.mark.parametrize("spec", ["ball:6", "flat:4", "bull:6:1"])
@pytest.mark.parametrize("indexing", ["ij", "xy"])
@pytest.mark.slow
def test_drop_cutter_grid_equals_scattered(spec, indexing):
    """A meshgrid of axes (either indexing, y descending) gives the heights and contacts the
    scattered path gives, discrete and refined."""
    f = lambda x, y: 0.4 * np.sin(0.7 * x) * np.cos(0.5 * y) + np.where(x > 0.3, 1.5, 0.0)
    zm = ZMap.from_function(f, (-12, -12, 12, 12), 0.1)
    X, Y = np.meshgrid(np.linspace(-5, 5, 11), np.linspace(-4, 4, 9)[::-1], indexing=indexing)
    for refine in (False, True):
        a = drop_cutter(zm, spec, X, Y, refine=refine, return_contact=True)
        b = drop_cutter(zm, spec, X.ravel(), Y.ravel(), refine=refine, return_contact=True)
        for u, v in zip(a, b):  # (cl, cx, cy, cz; cz is NaN where a flat's contact is on its rim)
            np.testing.assert_allclose(u, v.reshape(X.shape), rtol=0, atol=1e-12)
