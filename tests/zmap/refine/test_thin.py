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
from tests.reference import refine as ref
from zmap.refine.ez import QUANTUM_SHARE, THIN_SHARE, EZMap, build_ez, decimate

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
                       np.ascontiguousarray(seq[1:-1]), limit, 2, out)
    assert out[0] == ref.thin_intervals(seq, limit)


def test_decimate_keeps_walls_and_nan_edges_whole_and_holds_the_limit():
    f = SlopeWall()
    base = ZMap.from_function(f, (0, 0, 4, 4), 0.5)
    ez = build_ez(base, f, tol=TOL, eps_r=0.0, prune=False, verify=False, thin=False)
    h = ez.heights.copy()
    h[ez.offsets[3] + 5] = np.nan  # edge 3 has a missing height: kept whole
    off, hh, _ = decimate(base.z, base.dx, base.dy, ez.interval, TOL, ez.edge_ids, ez.offsets, h, THIN_SHARE * TOL)
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
    # each e-edge's codes in the bits their largest code (+1: the no-height code) needs, or
    # fewer (second differences along a smooth edge): the bit stream, a 4-bit width and a
    # mode bit per e-edge, a 4-bit difference width per differenced edge
    plain = sum(n * max(1, (int(ez.codes[o:o + n].max()) + 1).bit_length()) if n else 0
                for o, n in zip(ez.offsets[:-1].tolist(), np.diff(ez.offsets).tolist()))
    a = ez.to_arrays()
    nd = int(np.unpackbits(a["codes_mode"], count=ez.n_edges).sum())
    assert a["codes_bits"].size <= math.ceil(plain / 8)
    codes = a["codes_bits"].size + math.ceil(ez.n_edges / 2) + math.ceil(ez.n_edges / 8) + math.ceil(nd / 2)
    # header (version, grid, shape: 104 bytes), a bit per grid edge, a point count, an offset
    # (steps of the finest quantum, in the bits the largest needs) and a float16 quantum per
    # e-edge, the codes; a bit per e-edge, two bytes and a bit (its break a kink) per
    # windowed wall edge; no patches
    assert ez.n_windows >= 8 and a["step"].dtype == np.float16
    # quanta: one common value, a bit per edge, the others float16
    steps = sum(a[k].nbytes for k in ("step", "step_common", "step_is_common") if k in a)
    assert steps <= 2 * ez.n_edges
    k = np.rint((ez.lo.astype(np.float64) - float(ez.lo.min())) / (QUANTUM_SHARE * TOL)).astype(np.int64)
    lo_bytes = 24 + math.ceil(ez.n_edges * max(1, int(k.max()).bit_length()) / 8)
    assert "lo" not in a and a["lo_lattice"].nbytes + a["lo_k"].nbytes == lo_bytes < 4 * ez.n_edges
    n = np.diff(ez.offsets)  # point counts: in the bits the largest needs, behind their width
    w = int(n.max()).bit_length()
    cnt = 1 + math.ceil(ez.n_edges * w / 8) if w < 8 and ez.n_edges >= 16 else ez.n_edges
    assert ez.nbytes == (104 + math.ceil(E / 8) + cnt + lo_bytes + steps + codes
                         + math.ceil(ez.n_edges / 8) + 2 * ez.n_windows + math.ceil(ez.n_windows / 8))
    # fewer than 16 bits a code: smooth edges' ranges at the finest quantum
    assert plain < 16 * ez.n_points
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


# ---- windowed wall edges -------------------------------------------------------------------

@pytest.mark.slow
def test_wall_edges_keep_a_window_read_as_their_full_sequence():
    f = SlopeWall()
    base = ZMap.from_function(f, (0, 0, 4, 4), 0.5)
    full = build_ez(base, f, tol=TOL, eps_r=0.0, prune=False, thin=False, verify=False)
    ez = build_ez(base, f, tol=TOL, eps_r=0.0, prune=False, verify=False)
    kind, t = full.breaks(base)
    w = np.flatnonzero(ez.win >= 0)
    # every wall edge is windowed, and stores far fewer codes than its 49 samples
    assert set(w.tolist()) == set(np.flatnonzero(kind == 1).tolist()) and w.size >= 8
    assert np.diff(ez.offsets)[w].max() <= 12 and np.all(ez.full_counts()[w] == 49)
    # the kernels find the same breaks on the windowed sequences
    k2, t2 = ez.breaks(base)
    assert np.array_equal(kind, k2) and np.array_equal(t, t2)
    for k in w:
        eid = int(ez.edge_ids[k])
        a, b = ref.edge_sequence(full, base, eid), ref.edge_sequence(ez, base, eid)
        lo, c, _, _ = ez.window(int(k))
        # the window's samples are the full ones (to the coding); the rest within the thinning limit
        assert np.abs(a - b)[lo:c + 1].max() <= full.resolution + ez.resolution
        assert np.abs(a - b).max() <= THIN_SHARE * TOL + full.resolution + ez.resolution
    # the kernels read the windows as the slow reference does
    rng = np.random.default_rng(3)
    x, y = rng.uniform(0, 4, (2, 20000))
    h = ez.evaluate(base, x, y)
    r = ref.evaluate(ez, base, x, y)
    assert np.array_equal(np.isnan(h), np.isnan(r)) and np.nanmax(np.abs(h - r)) <= 1e-12
    # the stored points lie where the windows place them
    px, py = ez.points()
    assert np.abs(ez.heights - f(px, py)).max() <= THIN_SHARE * TOL + ez.resolution


def test_windowed_map_holds_tol_round_trips_and_old_files_load(tmp_path):
    f = SlopeWall(angle=1.1, c=2.6)
    base = ZMap.from_function(f, (0, 0, 4, 4), 0.5)
    ez = build_ez(base, f, tol=TOL, eps_r=0.0, prune=False)
    unwin = build_ez(base, f, tol=TOL, eps_r=0.0, prune=False, verify=False, thin=False)
    assert ez.n_windows >= 8 and ez.unresolved == 0
    rng = np.random.default_rng(9)
    x, y = rng.uniform(0, 4, (2, 40000))
    wall = np.abs(f.d(x, y)) < TOL
    assert np.abs(ez.height(base, x, y) - f(x, y))[~wall].max() <= TOL
    m = PrecisionModel(base, ez=ez, meta={"method": "ez"})
    back = PrecisionModel.load(m.save(tmp_path / "win.zpm"))
    assert np.array_equal(back.ez.win, ez.win) and np.array_equal(back.ez.offsets, ez.offsets)
    assert np.array_equal(back.height(x, y), m.height(x, y), equal_nan=True)
    # stored: a bit per e-edge and two bytes per windowed edge over the format-3 layout
    arrays = ez.to_arrays()
    assert arrays["win_b"].size == ez.n_windows and arrays["win_nl"].dtype == np.uint8
    # a format-3 map (no windows) loads and evaluates as before
    a3 = {k: v for k, v in unwin.to_arrays().items() if not k.startswith("win_")} | {"version": np.array([3])}
    old = EZMap.from_arrays(a3)
    assert old.n_windows == 0 and np.array_equal(old.evaluate(base, x, y), unwin.evaluate(base, x, y), equal_nan=True)
    # a window that does not fit its edge's stored count is refused, naming the edge
    bad = dict(arrays)
    bad["win_nl"] = arrays["win_nl"] + 40
    with pytest.raises(ValueError, match="window"):
        EZMap.from_arrays(bad)


def test_patch_sub_edges_may_keep_no_point_and_counts_pack_two_to_a_byte():
    from tests.zmap.refine.test_patch import Rib
    from zmap.refine.patch import CellPatches

    rib = Rib()
    base = ZMap.from_function(rib, (0, 0, 4, 4), 0.5)
    ez = build_ez(base, rib, tol=TOL)
    p = ez.patches
    assert p is not None and (p.counts[:p.edge_off[-1]] == 0).any()  # linear between sub-grid nodes
    arr = p.to_arrays()
    # a bit per sub-edge, the non-zero counts two to a byte where all are below 16, else in
    # the bits the largest needs (a level-2 sub-edge of 0.25 mm holds up to 24 points)
    nz = int(np.count_nonzero(p.counts))
    small = int(p.counts.max()) < 16
    assert arr["counts_nz"].size == (p.counts.size + 7) // 8
    assert (arr["counts4nz"].size == (nz + 1) // 2) if small else (arr["countsbnz"].size == (nz * int(arr["counts_bw"][0]) + 7) // 8)
    back = CellPatches.from_arrays(arr)
    assert np.array_equal(back.counts, p.counts)
    sub = CellPatches.pack({c: t for c, t in p.unpack().items() if int(t[0]) >= 4})  # no count above 15
    arr4 = sub.to_arrays()
    assert "counts4nz" in arr4 and arr4["counts4nz"].size == (int(np.count_nonzero(sub.counts)) + 1) // 2
    # every count two to a byte (the first format-5 files) still loads
    c = np.concatenate([sub.counts, np.zeros(sub.counts.size % 2, np.uint16)]).astype(np.uint8)
    old = {k: v for k, v in arr4.items() if not k.startswith("counts")} | {"counts4": c[0::2] | (c[1::2] << 4)}
    assert np.array_equal(CellPatches.from_arrays(old).counts, sub.counts)
    x, y = np.random.default_rng(5).uniform(0, 4, (2, 20000))
    from zmap.refine.patch import misfit

    assert not misfit(ez.height(base, x, y), x, y, rib(x, y), rib, TOL).any()


def test_quanta_are_stored_in_two_bytes_and_still_span_the_range():
    from zmap.refine._ecodec import half_step
    from zmap.refine.ez import encode_heights

    rng = np.random.default_rng(11)
    h = np.concatenate([rng.uniform(-50, 80, 40), [1.0, 1.0 + 3e-9], rng.uniform(0, 1e-4, 9), [2.0, 2.0]])
    off = np.array([0, 40, 42, 51, 53])
    codes, lo, step = encode_heights(off, h)
    assert np.array_equal(step.astype(np.float16).astype(np.float32), step)
    e = np.repeat(np.arange(4), np.diff(off))
    back = lo[e].astype(np.float64) + step[e].astype(np.float64) * codes
    span = np.array([np.ptp(h[a:b]) for a, b in zip(off[:-1], off[1:])])
    # the error stays within half the exact quantum (grown by float16's 1/1024) or 3e-8 mm
    assert np.all(np.abs(back - h) <= np.maximum(span[e] / 65534 / 2 * (1 + 2 ** -10), 3e-8) + 1e-6 * np.abs(h) * 2 ** -23)
    assert codes.max() <= 65534 and step[3] == 0.0
    assert np.all(half_step(np.array([1e-3, 5e-9])) >= np.array([1e-3, 5e-9], np.float32))
