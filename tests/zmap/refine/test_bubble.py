"""Bubbles: a Coons cell that misses over a smooth surface gets its centre height correction
(``16 u (1-u) v (1-v)`` times the exact centre height less the patch's) before a cell patch."""

from __future__ import annotations

import numpy as np
import pytest

from zmap import ZMap
from zmap.model import PrecisionModel
from tests.reference import refine as ref
from zmap.refine.ez import QUANTUM_SHARE, EZMap, build_ez
from zmap.refine.patch import misfit

TOL = 0.01


def egg_box(x, y):
    """Smooth and doubly curved (a large mixed derivative, the Coons patch's leading error) on a slope."""
    return 1.5 * np.sin(3.0 * x) * np.sin(3.0 * y) + 0.8 * x


@pytest.fixture(scope="module")
def egg():
    base = ZMap.from_function(egg_box, (0, 0, 4, 4), 0.5)
    return base, build_ez(base, egg_box, tol=TOL)


def test_bubbles_hold_cells_that_missed_and_the_model_holds_tol(egg):
    base, ez = egg
    assert ez.bub_cells.size >= 20
    # whole quanta, only on Coons cells, never on a patched cell
    q = QUANTUM_SHARE * TOL
    assert np.array_equal(np.rint(ez.bub_h / q) * q, ez.bub_h) and np.all(ez.bub_h != 0)
    assert np.array_equal(ez.coons_cells(base, ez.bub_cells), ez.bub_cells)
    if ez.n_patches:
        assert not np.isin(ez.bub_cells, ez.patches.cells).any()
    # without its bubble a bubble cell misses at its centre by more than the check allows
    ci, cj = np.divmod(ez.bub_cells, base.ny - 1)
    xc, yc = base.x0 + (ci + 0.5) * base.dx, base.y0 + (cj + 0.5) * base.dy
    h = ez.height(base, xc, yc)
    bare = h - ez.bub_h
    assert np.abs(h - egg_box(xc, yc)).max() <= 0.5 * q + 1e-12  # the centre: exact to the quantum
    assert np.abs(bare - egg_box(xc, yc)).max() > TOL
    # random points: within tol (the misfit rule: vertically where gentle, in 3D by probes where steep)
    x, y = np.random.default_rng(4).uniform(0, 4, (2, 30000))
    hm = ez.height(base, x, y)
    assert not misfit(hm, x, y, egg_box(x, y), egg_box, TOL).any()


def test_bubbles_cost_less_than_the_patches_they_replace(egg):
    base, ez = egg
    plain = build_ez(base, egg_box, tol=TOL, verify=False)  # the same e-map, nothing checked
    assert plain.bub_cells.size == 0
    # each bubble: its cell id and a few bits; a level-2 patch: 9 nodes and 12 sub-edges
    a = ez.to_arrays()
    assert a["bub_codes"].size + a["bub_cells"].nbytes + a["bub_q"].nbytes <= 6 * ez.bub_cells.size + 16


@pytest.mark.slow
def test_bubbles_round_trip_and_the_kernels_agree_with_the_reference(egg, tmp_path):
    base, ez = egg
    back = EZMap.from_arrays(ez.to_arrays())
    assert np.array_equal(back.bub_cells, ez.bub_cells) and np.array_equal(back.bub_h, ez.bub_h)
    m = PrecisionModel(base, ez=ez)
    m2 = PrecisionModel.load(m.save(tmp_path / "egg.zpm"))
    rng = np.random.default_rng(7)
    ci, cj = np.divmod(ez.bub_cells, base.ny - 1)
    u, v = rng.uniform(0, 1, (2, ci.size, 6))
    x = (base.x0 + (ci[:, None] + u) * base.dx).ravel()
    y = (base.y0 + (cj[:, None] + v) * base.dy).ravel()
    want = m.height(x, y)
    assert np.array_equal(m2.height(x, y), want)
    # the point-by-point reference adds the same bubble
    k = np.arange(0, x.size, 7)
    assert np.allclose(ref.evaluate(ez, base, x[k], y[k]), ez.evaluate(base, x[k], y[k]), rtol=0, atol=1e-9)
    # the drop-cutter's numba evaluation too
    from zmap.cam import _model_eval as ME

    M = ME.pack_model(m)
    out = np.empty(x.size)
    ME.heights(M, np.ascontiguousarray(x), np.ascontiguousarray(y), out, 0, x.size)
    assert np.allclose(out, want, rtol=0, atol=1e-9)


def test_bad_bubbles_are_refused(egg):
    base, ez = egg
    a = ez.to_arrays()
    with pytest.raises(ValueError, match="bubble"):
        EZMap.from_arrays(a | {"bub_codes": a["bub_codes"][:-1]})
    with pytest.raises(ValueError, match="bubbles"):
        EZMap(ez.x0, ez.y0, ez.dx, ez.dy, ez.nx, ez.ny, ez.interval, ez.tol, ez.edge_ids, ez.offsets, ez.codes,
              ez.lo, ez.step, bub_cells=np.array([3, 2]), bub_h=np.array([0.1, 0.2]))
