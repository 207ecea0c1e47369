"""Verified EZ cells (zmap.refine.patch): pruning, cell patches, lattices, storage.

A thin rib (two walls inside one base cell) is the case the paper's Coons patch cannot
hold; its exact 3D distance is the distance in the cross-section plane (d, z) to the rib's
outline, so the checks below measure the model against an independent truth.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from zmap import ZMap
from zmap.model import PrecisionModel
from zmap.refine.ez import QUANTUM_SHARE, EZMap, build_ez
from zmap.refine.patch import (
    CellPatches,
    build_lattices,
    failing_cells,
    lattice_intervals,
    misfit,
    patch_failing,
)

TOL = 0.01


class Rib:
    """z = H where |n.(x, y) - c| < w/2, else 0: a rib thinner than a grid cell."""

    def __init__(self, angle=0.3, c=2.03, w=0.2, H=5.0):
        self.n = np.array([math.cos(angle), math.sin(angle)])
        self.c, self.a, self.H = c, w / 2, H

    def d(self, x, y):
        return self.n[0] * x + self.n[1] * y - self.c

    def __call__(self, x, y):
        return np.where(np.abs(self.d(x, y)) < self.a, self.H, 0.0)

    def se_curves(self):
        """The rib's two top edges as xy polylines across the 4 x 4 domain (sharp edges: a
        rib thinner than a cell can pass between grid points, only the B-rep's edges find it)."""
        t = np.array([-self.n[1], self.n[0]])
        return [np.array([(self.c + s) * self.n - 10 * t, (self.c + s) * self.n + 10 * t]) for s in (-self.a, self.a)]

    def distance(self, x, y, z):
        """Exact 3D distance from (x, y, z) to the rib's surface (floor, two walls, top)."""
        e = np.abs(self.d(x, y)) - self.a  # > 0 outside the rib
        floor = np.where(e >= 0, np.abs(z), np.hypot(e, z))
        wall = np.hypot(e, z - np.clip(z, 0.0, self.H))
        top = np.where(e <= 0, np.abs(z - self.H), np.hypot(e, z - self.H))
        return np.minimum(np.minimum(floor, wall), top)


def near_rib(rib, rng, n, band=0.4):
    x, y = rng.uniform(0, 4, 4 * n), rng.uniform(0, 4, 4 * n)
    keep = np.abs(rib.d(x, y)) < band
    return x[keep][:n], y[keep][:n]


def test_thin_rib_needs_patches_and_patched_cells_hold_tol():
    rib = Rib()
    base = ZMap.from_function(rib, (0, 0, 4, 4), 0.5)
    rng = np.random.default_rng(0)
    x, y = near_rib(rib, rng, 30000)
    plain = build_ez(base, rib, tol=TOL, se_curves=rib.se_curves(), verify=False)
    # the premise: two walls in one cell are beyond the paper's split Coons patch
    assert rib.distance(x, y, plain.height(base, x, y)).max() > 0.1
    ez = build_ez(base, rib, tol=TOL, se_curves=rib.se_curves())
    assert ez.n_patches > 0 and ez.unresolved == 0
    h = ez.height(base, x, y)
    assert np.isfinite(h).all()
    assert rib.distance(x, y, h).max() <= TOL
    # and the patched cells are the ones the rib runs through
    assert set(failing_cells(lambda a, b: plain.height(base, a, b), base, rib, 0.9 * TOL,
                             ez.patches.cells)) <= set(ez.patches.cells.tolist())


def test_lattice_holds_tol_by_construction():
    """The last resort alone: every misfit cell as a dense lattice, bilinear, diagonal <= tol."""
    rib = Rib(angle=1.1, c=2.4, w=0.13)
    base = ZMap.from_function(rib, (0, 0, 4, 4), 0.5)
    ez = build_ez(base, rib, tol=TOL, se_curves=rib.se_curves(), verify=False)
    cells = np.flatnonzero(ez.cell_mask().ravel())

    def install(p):
        ez.patches = p if p.n_patches else None
        ez._cache = {}

    broken = ez._tables(base)["ecell_ids"][ez._tables(base)["nb"] > 0]
    patches, still = patch_failing(lambda a, b: ez.height(base, a, b), base, rib, TOL, ez.interval, cells, install,
                                   levels=(), fine_cells=broken)
    assert still.size == 0 and patches.n_patches > 0 and (patches.level < 0).all()
    n = lattice_intervals(base, TOL)
    assert math.hypot(base.dx / n, base.dy / n) <= TOL
    rng = np.random.default_rng(1)
    x, y = near_rib(rib, rng, 30000)
    assert rib.distance(x, y, ez.height(base, x, y)).max() <= TOL


def test_pruning_keeps_what_the_base_misses_and_drops_smooth_slopes():
    def f(x, y):  # a steep smooth slope (0.4 to 0.5, eps_r is 0.04) with a wall
        return 0.4 * x + 0.1 * np.sin(y) + np.where(y > 0.37 * x + 1.1, 2.0, 0.0)

    base = ZMap.from_function(f, (0, 0, 6, 4), 0.5)
    full = build_ez(base, f, tol=TOL, prune=False, verify=False)
    ez = build_ez(base, f, tol=TOL)
    assert ez.pruned > 0 and ez.n_edges < 0.6 * full.n_edges and ez.nbytes < full.nbytes
    rng = np.random.default_rng(2)
    x, y = rng.uniform(0, 6, 40000), rng.uniform(0, 4, 40000)
    h = ez.height(base, x, y)
    z = f(x, y)
    wall = np.abs(y - 0.37 * x - 1.1) / math.hypot(1, 0.37) < TOL
    assert np.abs(h - z)[~wall].max() <= TOL
    assert not misfit(h, x, y, z, f, TOL).any()


def test_model_round_trip_with_patches_and_lattices(tmp_path):
    rib = Rib()
    base = ZMap.from_function(rib, (0, 0, 4, 4), 0.5)
    ez = build_ez(base, rib, tol=TOL)
    # add a lattice patch to a cell without one, so both kinds travel through the file
    per = ez.patches.unpack()
    free = next(c for c in range(ez.nx * ez.ny) if c not in per)
    per.update(build_lattices(base, rib, np.array([free]), 9))
    ez.patches = CellPatches.pack(per)
    ez._cache = {}
    m = PrecisionModel(base, ez=ez, meta={"method": "ez"})
    back = PrecisionModel.load(m.save(tmp_path / "rib.zpm"))
    assert back.ez.n_patches == ez.n_patches and back.ez.pruned == ez.pruned
    for name, a in ez.patches.to_arrays().items():
        assert np.array_equal(a, back.ez.patches.to_arrays()[name], equal_nan=True), name
    for name in ("nodes", "codes", "lo", "step", "counts", "node_off", "code_off", "edge_off"):
        assert np.array_equal(getattr(ez.patches, name), getattr(back.ez.patches, name), equal_nan=True), name
    rng = np.random.default_rng(3)
    x, y = rng.uniform(0, 4, 5000), rng.uniform(0, 4, 5000)
    assert np.array_equal(m.height(x, y), back.height(x, y), equal_nan=True)
    assert m.nbytes["ez"] == ez.nbytes > ez.patch_nbytes > 0


def test_version_1_e_map_arrays_still_load():
    rib = Rib()
    base = ZMap.from_function(rib, (0, 0, 4, 4), 0.5)
    ez = build_ez(base, rib, tol=TOL, verify=False)
    a = {k: v for k, v in ez.to_arrays().items() if not k.startswith("patch_")}
    a["version"] = np.array([1])
    a["shape"] = a["shape"][:4]
    old = EZMap.from_arrays(a)
    assert old.patches is None and old.n_edges == ez.n_edges and old.pruned == 0


def test_misfit_nan_rules():
    f = lambda x, y: np.where(x < 1.0, np.nan, 2.0)
    x = np.array([0.5, 0.995, 1.5, 1.5])
    y = np.zeros(4)
    h = np.array([2.0, 2.0, np.nan, 2.5])
    # a height over no surface misses unless a surface is within tol; no height never misses
    assert misfit(h, x, y, f(x, y), f, TOL).tolist() == [True, False, False, True]


def test_bad_patch_arrays():
    rib = Rib()
    base = ZMap.from_function(rib, (0, 0, 4, 4), 0.5)
    a = build_ez(base, rib, tol=TOL).patches.to_arrays()
    key = next(k for k in ("counts4nz", "countsbnz", "counts") if k in a)
    bad = dict(a, **{key: a[key][:-2]})
    with pytest.raises(ValueError, match="counts"):
        CellPatches.from_arrays(bad)
    bad = dict(a, codes_bits=a["codes_bits"][:-1])
    with pytest.raises(ValueError, match="bytes of codes"):
        CellPatches.from_arrays(bad)
    old = {k: v for k, v in a.items() if not k.startswith("codes_")}  # format 4: 16-bit codes
    p = CellPatches.from_arrays(a)
    node_codes = np.rint((p.nodes - np.repeat(p.lo[p.edge_off[:-1]], np.diff(p.node_off)))
                         / np.repeat(p.step[p.edge_off[:-1]], np.diff(p.node_off))).astype(np.uint16)
    assert np.array_equal(CellPatches.from_arrays(old | {"codes": p.codes, "node_codes": node_codes}).nodes, p.nodes)
    bad = dict(old, codes=p.codes[:-1], node_codes=node_codes)
    with pytest.raises(ValueError, match="offsets"):
        CellPatches.from_arrays(bad)
    # format 6 stores the cells as the bits of their gaps; format 5 as ids
    ids = {k: v for k, v in a.items() if k not in ("cells_gaps", "cells_w")}
    assert np.array_equal(CellPatches.from_arrays(ids | {"cells": p.cells.astype(np.uint32)}).cells, p.cells)
    with pytest.raises(ValueError, match="increasing"):
        CellPatches.from_arrays(ids | {"cells": p.cells[::-1].astype(np.uint32)})
    with pytest.raises(ValueError, match="cells"):
        CellPatches.from_arrays(dict(a, cells_gaps=a["cells_gaps"][:-1]))


def test_stacked_kernel_matches_each_patch_on_its_own():
    rib = Rib(angle=0.8, c=2.6, w=0.17)
    base = ZMap.from_function(rib, (0, 0, 4, 4), 0.5)
    ez = build_ez(base, rib, tol=TOL, se_curves=rib.se_curves())
    p = ez.patches
    assert (p.level > 0).sum() >= 2
    rng = np.random.default_rng(5)
    for k in np.flatnonzero(p.level > 0):
        sub, one = p._patch_maps(int(k), base, ez.interval, ez.tol)
        x, y = rng.uniform(sub.x0, sub.x0 + base.dx, 500), rng.uniform(sub.y0, sub.y0 + base.dy, 500)
        alone = one.evaluate(sub, x, y)
        out = np.full(x.size, np.nan)
        p.evaluate(base, ez.interval, ez.tol, x, y, out)
        assert np.array_equal(alone, out, equal_nan=True)


@pytest.mark.slow
def test_real_part_ez_holds_tol_in_3d(sample_data):
    """featuretype.STEP (a machined block: pockets, holes, chamfers), grid 0.5, tol 0.01: the
    checked EZ model stays within tol of the B-rep at random points where the paper's EZ
    alone (verify=False) does not, and within 3x the base's memory."""
    cad_io = pytest.importorskip("cad_io")
    from cad_io.refine import RefineOptions, refine_models
    from cad_io.distance import confirm_with_occ, distance_to_part
    from cad_io.sampler import height_function
    from zmap.features import sharp_edge_curves

    part = cad_io.read_step(sample_data / "step" / "featuretype.STEP")
    base = cad_io.sample(part, 0.5)
    model, info = refine_models(part, base, RefineOptions(TOL, ("ez",)))["ez"]
    ez = model.ez
    assert ez.unresolved == 0 and ez.n_patches > 0 and ez.pruned > 0
    assert model.nbytes["total"] <= 3.0 * model.nbytes["base"]
    plain = build_ez(base, height_function(part, deflection=TOL / 2), tol=TOL, se_curves=sharp_edge_curves(part.edges),
                     verify=False)
    rng = np.random.default_rng(7)
    # random points in the patched cells and over the whole part
    k = rng.integers(0, ez.n_patches, 3000)
    ci, cj = np.divmod(ez.patches.cells[k], base.ny - 1)
    x = np.concatenate([base.x0 + (ci + rng.random(k.size)) * base.dx, rng.uniform(base.x0, base.x1, 20000)])
    y = np.concatenate([base.y0 + (cj + rng.random(k.size)) * base.dy, rng.uniform(base.y0, base.y1, 20000)])

    def dist(h):
        ok = np.isfinite(h)
        pts = np.c_[x[ok], y[ok], h[ok]]
        d, _, left = confirm_with_occ(part, pts, distance_to_part(part, pts, deflection=TOL / 2), above=TOL / 2)
        assert left == 0
        return d

    # the premise: without the cell check the EZ misses by several tolerances (0.070 mm measured)
    assert dist(plain.height(base, x, y)).max() > 5 * TOL
    assert dist(model.height(x, y)).max() <= TOL


def test_format_2_patch_arrays_load_recoded_on_one_scale_per_patch():
    rib = Rib()
    base = ZMap.from_function(rib, (0, 0, 4, 4), 0.5)
    ez = build_ez(base, rib, tol=TOL, thin=False)
    p = ez.patches
    # format 2 stored every array as it is held, a scale per sub-edge and float64 nodes
    legacy = {"cells": p.cells, "level": p.level, "node_off": p.node_off, "nodes": p.nodes, "code_off": p.code_off,
              "codes": p.codes, "edge_off": p.edge_off, "lo": p.lo, "step": p.step}
    back = CellPatches.from_arrays(legacy, grid=(base.dx, base.dy, ez.interval))
    assert np.array_equal(back.counts, p.counts) and np.array_equal(back.code_off, p.code_off)
    x, y = np.random.default_rng(4).uniform(0, 4, (2, 5000))
    a, b = np.full(x.size, np.nan), np.full(x.size, np.nan)
    p.evaluate(base, ez.interval, ez.tol, x, y, a)
    back.evaluate(base, ez.interval, ez.tol, x, y, b)
    # re-coded on the patch's range: heights move by at most one quantum of it
    assert np.nanmax(np.abs(a - b)) <= 2 * float(back.step.max()) and np.array_equal(np.isnan(a), np.isnan(b))
    with pytest.raises(ValueError, match="format 2"):
        CellPatches.from_arrays(legacy)


def test_sub_lattices_over_the_missing_sub_cells_hold_tol_and_cost_less(tmp_path):
    """The last resort over a coarse patch level: lattices on only the sub-cells that miss."""
    from zmap.refine.patch import build_sub_lattices, sub_lattice_intervals

    rib = Rib(angle=1.1, c=2.4, w=0.13)
    base = ZMap.from_function(rib, (0, 0, 4, 4), 0.5)
    ez = build_ez(base, rib, tol=TOL, se_curves=rib.se_curves(), verify=False)
    cells = np.flatnonzero(ez.cell_mask().ravel())

    def install(p):
        ez.patches = p if p.n_patches else None
        ez._cache = {}

    broken = ez._tables(base)["ecell_ids"][ez._tables(base)["nb"] > 0]
    patches, still = patch_failing(lambda a, b: ez.height(base, a, b), base, rib, TOL, ez.interval, cells, install,
                                   levels=(4,), fine_cells=broken)
    subs = patches.subs
    assert still.size == 0 and subs is not None and subs.n > 0
    m, n = subs.mn.tolist()
    assert m == 4 and n == sub_lattice_intervals(base, TOL, 4) and math.hypot(base.dx / m / n, base.dy / m / n) <= TOL
    # sub-lattices sit in level-4 patches, and cost less than whole-cell lattices would
    assert set((subs.keys // 16).tolist()) <= set(patches.cells[patches.level == 4].tolist())
    assert subs.codes.nbytes < 2 * (lattice_intervals(base, TOL) + 1) ** 2 * np.unique(subs.keys // 16).size
    rng = np.random.default_rng(1)
    x, y = near_rib(rib, rng, 30000)
    assert rib.distance(x, y, ez.height(base, x, y)).max() <= TOL
    # a sub-lattice answers bilinearly from its own corners: at a lattice node, the exact height
    k = subs.keys[0]
    one = build_sub_lattices(base, rib, np.array([k]), m, n, QUANTUM_SHARE * TOL)
    c, r = divmod(int(k), m * m)
    ci, cj = divmod(c, base.ny - 1)
    xn = base.x0 + (ci + (r // m + 0.5) / m) * base.dx
    yn = base.y0 + (cj + (r % m + 0.5) / m) * base.dy
    assert np.array_equal(one.codes, subs.codes[:one.codes.size])
    assert abs(float(ez.height(base, np.array([xn]), np.array([yn]))[0]) - float(rib(xn, yn))) <= TOL
    m_ = PrecisionModel(base, ez=ez, meta={"method": "ez"})
    back = PrecisionModel.load(m_.save(tmp_path / "subs.zpm"))
    assert back.ez.patches.subs is not None and np.array_equal(back.ez.patches.subs.keys, subs.keys)
    assert np.array_equal(back.height(x, y), m_.height(x, y), equal_nan=True)
    # format 6 packs a lattice row a segment; format 5's lattice a segment still loads
    from zmap.refine._emap import pack_codes
    from zmap.refine.patch import SubLattices

    a = subs.to_arrays()
    assert "rows" in a
    f5 = {k: v for k, v in a.items() if k != "rows" and not k.startswith("codes_")} | {
        f"codes_{k}": v for k, v in pack_codes(subs.codes, np.arange(subs.n + 1) * (n + 1) ** 2).items()}
    old = SubLattices.from_arrays(f5)
    assert np.array_equal(old.codes, subs.codes) and np.array_equal(old.lo, subs.lo)


def test_misfit_holds_gentle_slopes_to_tol_vertically():
    # on a slope of 0.8 the probes (up to 0.75 tol away) bracket a point 1.05 tol off vertically
    # within tol/2, which would excuse it on a steep face; on a gentle one it misses
    f = lambda x, y: 0.8 * x + 0.0 * y
    x, y = np.array([1.0, 1.0, 1.0]), np.zeros(3)
    h = f(x, y) + np.array([1.05 * TOL, 0.95 * TOL, -1.05 * TOL])
    assert misfit(h, x, y, f(x, y), f, TOL).tolist() == [True, False, True]
    steep = lambda x, y: 1.6 * x + 0.0 * y  # steeper than 1: the bracket still excuses it
    assert not misfit(steep(x, y) + 1.05 * TOL, x, y, steep(x, y), steep, TOL).any()
    # gentle along x and y (0.83), 1.17 along the diagonal: held to tol, as Table 2 counts it
    diag = lambda x, y: 0.83 * x + 0.83 * y
    assert misfit(diag(x, y) + 1.05 * TOL, x, y, diag(x, y), diag, TOL).all()


def test_patches_pass_nan_points_by_without_a_cast_warning():
    """A NaN point (a caller's "no point") lies in no patched cell: its height stays as given,
    and no NaN is cast to a cell index (numpy's RuntimeWarning, seen in the suite's log)."""
    import warnings

    rib = Rib()
    base = ZMap.from_function(rib, (0, 0, 4, 4), 0.5)
    ez = build_ez(base, rib, tol=TOL, se_curves=rib.se_curves())
    assert ez.n_patches > 0
    x = np.array([np.nan, 2.0, 1.0])
    y = np.array([1.0, np.nan, np.nan])
    out = np.array([7.0, 8.0, 9.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ez.patches.evaluate(base, ez.interval, ez.tol, x, y, out)
    assert out.tolist() == [7.0, 8.0, 9.0]


def crest(x_c=2.5, half_width=0.3, height=0.03):
    """z = a tent of ``height`` over ``|x - x_c| < half_width``: a crest narrower than a cell."""
    return lambda x, y: height * np.clip(1.0 - np.abs(np.asarray(x) - x_c) / half_width, 0.0, None)


def test_a_crest_between_two_test_points_is_found_where_the_error_bends():
    """Grid 2 mm, tol 0.02: the 8 x 8 test lattice's points are 0.25 mm apart, and a crest
    0.03 mm high between two of them leaves 0.0175 mm at both (within the check's 0.018);
    the error's turn there sends the cell to a 4x finer lattice, which finds the crest."""
    exact = crest()
    flat = lambda x, y: np.zeros_like(np.asarray(x, dtype=np.float64))  # noqa: E731
    base = ZMap.from_function(flat, (0, 0, 8, 8), 2.0)
    cells = np.arange((base.nx - 1) * (base.ny - 1), dtype=np.int64)
    crest_cell = 1 * (base.ny - 1) + 0  # x in [2, 4], y in [0, 2]
    # the premise: the plain lattice steps over the crest
    assert failing_cells(flat, base, exact, 0.9 * 0.02, cells).size == 0
    found = failing_cells(flat, base, exact, 0.9 * 0.02, cells, bend=True)
    assert crest_cell in found.tolist()
    assert set(found.tolist()) == {i * (base.ny - 1) + j for i in (1,) for j in range(base.ny - 1)}


def angled_ridge(angle=0.15, crest_height=0.03):
    """A ridge 3 mm high and 2.6 mm wide at its foot, across the grid at ``angle``, with a
    narrow crest on top: two concave kinks at its feet and a crest the grid's cells cross."""
    c, s = math.cos(angle), math.sin(angle)

    def f(x, y):
        d = c * np.asarray(x, dtype=np.float64) + s * np.asarray(y, dtype=np.float64) - 4.55
        return 3.0 * np.clip(1 - np.abs(d) / 1.3, 0, None) + crest_height * np.clip(1 - np.abs(d) / 0.25, 0, None)

    return f


def test_ez_holds_tol_where_a_kink_bends_its_error_between_test_points():
    """Grid 2, tol 0.02: the model rounds the ridge's concave foot, 0.04 mm above the floor
    in a band 0.016 mm wide, which the patch's 32 x 32 re-test lattice steps over; the
    error's turn sends the cell to a 4x finer lattice and a finer patch."""
    tol = 0.02
    ridge = angled_ridge()
    base = ZMap.from_function(ridge, (0, 0, 10, 8), 2.0)
    ez = build_ez(base, ridge, tol=tol)
    assert ez.unresolved == 0
    x, y = np.meshgrid(np.linspace(0, 10, 801), np.linspace(0, 8, 641), indexing="ij")
    x, y = x.ravel(), y.ravel()
    h = ez.height(base, x, y)
    assert not misfit(h, x, y, ridge(x, y), ridge, tol).any()


def test_ez_heights_on_the_maps_far_sides_are_the_heights_beside_them():
    """A split cell (a kink runs through it) on the map's top or right side: a point on that
    side lies on the cell's boundary, where the side-of-the-trace test once counted no
    crossing and took the other side's data (0 instead of 0.58 mm)."""
    ridge = angled_ridge(angle=0.0)
    along_y = lambda x, y: ridge(y, x)  # noqa: E731
    for f, domain, swap in ((ridge, (0, 0, 10, 8), False), (along_y, (0, 0, 8, 10), True)):
        base = ZMap.from_function(f, domain, 2.0)
        ez = build_ez(base, f, tol=0.02, verify=False)
        s = np.array([3.5, 4.5, 5.5, 7.0])
        for edge in (8.0, 8.0 - 1e-9):
            xy = (np.full(4, edge), s) if swap else (s, np.full(4, edge))
            np.testing.assert_allclose(ez.height(base, *xy), f(*xy), atol=0.01)
