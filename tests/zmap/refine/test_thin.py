"""Thinned e-points: smooth edges keep every s-th e-point, walls keep all (``build_ez(thin=True)``)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zmap import ZMap
from zmap.model import PrecisionModel
from zmap.refine import _ez_kernels as _k
from zmap.refine import _reference as ref
from zmap.refine._emap import decimate
from zmap.refine.ez import THIN_SHARE, EZMap, build_ez

TOL = 0.01


class SlopeWall:
    """A steep plane z = 3 x + y with a 4 mm wall along a tilted line on top of it."""

    def __init__(self, angle=0.4, c=2.1):
        self.n = np.array([math.cos(angle), math.sin(angle)])
        self.c = c

    def d(self, x, y):
        return self.n[0] * x + self.n[1] * y - self.c

    def __call__(self, x, y):
        return 3.0 * x + y + np.where(self.d(x, y) > 0, 4.0, 0.0)


@settings(max_examples=60, deadline=None)
@given(st.sampled_from([10, 13, 24, 50, 7]), st.integers(0, 2**31 - 1), st.floats(0.0, 0.02),
       st.floats(0.001, 0.05))
def test_kernel_counts_match_reference(m, seed, noise, limit):
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, m + 1)
    seq = 2.0 * t + 0.3 * t ** 2 + noise * rng.standard_normal(m + 1)
    z = np.array([[seq[0]], [seq[-1]]])  # a 2 x 1 grid: one x-edge, id 0
    out = np.empty(1, dtype=np.int64)
    _k.decimate_counts(z, np.array([0], np.int64), np.array([0, m - 1], np.int64),
                       np.ascontiguousarray(seq[1:-1]), limit, out)
    assert out[0] == ref.thin_intervals(seq, limit)


def test_decimate_keeps_walls_and_nan_edges_whole_and_holds_the_limit():
    f = SlopeWall()
    base = ZMap.from_function(f, (0, 0, 4, 4), 0.5)
    ez = build_ez(base, f, tol=TOL, eps_r=0.0, prune=False, verify=False, thin=False)
    h = ez.heights.copy()
    h[ez.offsets[3] + 5] = np.nan  # edge 3 has a missing height: kept whole
    off, hh = decimate(base.z, base.dx, base.dy, ez.interval, TOL, ez.edge_ids, ez.offsets, h, THIN_SHARE * TOL)
    n0, n1 = np.diff(ez.offsets), np.diff(off)
    thin = EZMap.from_heights(ez.x0, ez.y0, ez.dx, ez.dy, ez.nx, ez.ny, ez.interval, TOL, ez.edge_ids, off, hh)
    kind, _ = ez.breaks(base)
    assert np.all(n1[kind != 0] == n0[kind != 0]) and (kind != 0).sum() >= 8
    assert n1[3] == n0[3]
    assert np.all(n1[kind == 0][4:] == 1)  # a plane needs no e-point but the midpoint
    # the new points lie on the full sequence (linear between its samples) at t = q / (c + 1)
    for k in range(ez.n_edges):
        seq = ref.edge_sequence(ez, base, int(ez.edge_ids[k]))
        seq[1:-1] = h[ez.offsets[k]:ez.offsets[k + 1]]
        m, c = n0[k] + 1, n1[k]
        want = np.interp(np.arange(1, c + 1) * m / (c + 1), np.arange(m + 1), seq)
        np.testing.assert_allclose(hh[off[k]:off[k + 1]], want, rtol=0, atol=1e-12)
    x, y = np.random.default_rng(1).uniform(0, 4, (2, 20000))
    ok = ~np.isnan(ez.evaluate(base, x, y))
    full_ez = EZMap.from_heights(ez.x0, ez.y0, ez.dx, ez.dy, ez.nx, ez.ny, ez.interval, TOL, ez.edge_ids,
                                 ez.offsets, h)
    d = np.abs(thin.evaluate(base, x, y) - full_ez.evaluate(base, x, y))[ok]
    assert np.nanmax(d) <= 2 * THIN_SHARE * TOL + 2 * thin.resolution


def test_thinned_model_holds_tol_with_less_memory(tmp_path):
    f = SlopeWall()
    base = ZMap.from_function(f, (0, 0, 4, 4), 0.5)
    full = build_ez(base, f, tol=TOL, eps_r=0.0, prune=False, thin=False)
    thin = build_ez(base, f, tol=TOL, eps_r=0.0, prune=False)
    assert thin.n_edges == full.n_edges and thin.n_points < 0.5 * full.n_points
    assert thin.nbytes < 0.6 * full.nbytes and thin.unresolved == 0
    rng = np.random.default_rng(7)
    x, y = rng.uniform(0, 4, (2, 40000))
    z = f(x, y)
    wall = np.abs(f.d(x, y)) < TOL  # within tol of the wall: the wall itself is the surface there
    h = thin.height(base, x, y)
    assert np.abs(h - z)[~wall].max() <= TOL
    # the file holds the thinned map exactly
    m = PrecisionModel(base, ez=thin, meta={"method": "ez"})
    back = PrecisionModel.load(m.save(tmp_path / "thin.zpm"))
    assert np.array_equal(back.ez.offsets, thin.offsets) and np.array_equal(back.ez.edge_ids, thin.edge_ids)
    assert np.array_equal(back.height(x, y), m.height(x, y), equal_nan=True)


def test_stored_bytes_are_bits_counts_codes_and_scales():
    f = SlopeWall()
    base = ZMap.from_function(f, (0, 0, 4, 4), 0.5)
    ez = build_ez(base, f, tol=TOL, verify=False)
    from zmap.refine.ez import edge_count

    E = edge_count(base.nx, base.ny)
    # header (version, grid, shape: 104 bytes), a bit per grid edge, a byte count, two float32
    # scales per e-edge, two bytes per e-point; no patches
    assert ez.nbytes == 104 + math.ceil(E / 8) + 9 * ez.n_edges + 2 * ez.n_points
    assert ez.index_nbytes == 8 * (2 * ez.n_edges + 1)


@pytest.mark.parametrize("thin", [False, True])
def test_patches_thin_their_sub_edges(thin):
    from tests.zmap.refine.test_patch import Rib

    rib = Rib()
    base = ZMap.from_function(rib, (0, 0, 4, 4), 0.5)
    ez = build_ez(base, rib, tol=TOL, thin=thin)
    p = ez.patches
    assert p is not None and (p.level > 0).any()
    full = np.diff(p.edge_off)[p.level > 0].sum()
    assert (p.counts.size == p.lo.size) and full > 0
    x, y = np.random.default_rng(2).uniform(0, 4, (2, 20000))
    z = rib(x, y)
    from zmap.refine.patch import misfit

    assert not misfit(ez.height(base, x, y), x, y, z, rib, TOL).any()
