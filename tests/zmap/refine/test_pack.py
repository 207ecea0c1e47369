"""Formats 5 and 6 of the e-map: codes stored in the bits their range needs at the finest
quantum, forced breaks on windowed edges (the full sequence's, not re-detected), and (6) the
edges' offsets as steps of the finest quantum."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from zmap import ZMap
from zmap.model import PrecisionModel
from zmap.refine import _ez_kernels as _k
from tests.reference import refine as ref
from zmap.refine._ecodec import pack_offsets, unpack_offsets
from zmap.refine._emap import WINDOW_HALF, pack_codes, unpack_codes
from zmap.refine.ez import BREAK_RATIO, NAN_CODE, QUANTUM_SHARE, EZMap, build_ez, encode_heights

from .test_thin import TOL, SlopeWall


@settings(max_examples=80, deadline=None)
@given(st.lists(st.lists(st.integers(0, NAN_CODE), min_size=0, max_size=9), min_size=0, max_size=12))
def test_packed_codes_round_trip(segments):
    codes = np.array([c for s in segments for c in s], dtype=np.uint16)
    off = np.concatenate([[0], np.cumsum([len(s) for s in segments])]).astype(np.int64)
    a = pack_codes(codes, off)
    assert np.array_equal(unpack_codes(a["bits"], a["w4"], off, a["mode"], a["r4"]), codes)
    # a segment takes the bits of its largest code + 1 (the no-height code is all ones), or
    # fewer with its second differences (4 bits for their width)
    plain = [len(s) * max(1, (max([c for c in s if c != NAN_CODE], default=0) + 1).bit_length()) for s in segments]
    mode = np.unpackbits(a["mode"], count=len(segments)).astype(bool)
    assert a["bits"].size <= (sum(plain) + 7) // 8 and a["w4"].size == (len(segments) + 1) // 2
    assert a["r4"].size == (int(mode.sum()) + 1) // 2
    assert all(len(s) >= 3 and NAN_CODE not in s for s, md in zip(segments, mode) if md)


def test_smooth_segments_are_stored_as_second_differences():
    q = np.arange(12)
    smooth = np.rint(40000 + 900 * q - 3.0 * q ** 2).astype(np.uint16)  # 16 bits plain
    wall = np.where(q < 6, 100, 60000).astype(np.uint16)
    off = np.array([0, 12, 24, 24], dtype=np.int64)  # and an empty segment
    codes = np.concatenate([smooth, wall])
    a = pack_codes(codes, off)
    mode = np.unpackbits(a["mode"], count=3).astype(bool)
    assert mode.tolist() == [True, False, False]
    # the smooth run: two codes of 16 bits, ten second differences of -6 (zigzag 11: 4 bits)
    assert a["bits"].size == (2 * 16 + 10 * 4 + 12 * 16 + 7) // 8
    assert np.array_equal(unpack_codes(a["bits"], a["w4"], off, a["mode"], a["r4"]), codes)
    # without the mode bits (the first format-5 files) every segment is plain
    p = pack_codes(codes[12:], np.array([0, 12], dtype=np.int64))
    assert np.array_equal(unpack_codes(p["bits"], p["w4"], np.array([0, 12], dtype=np.int64)), codes[12:])


def test_quantum_floor_bounds_the_error_and_the_codes():
    rng = np.random.default_rng(4)
    h = np.concatenate([rng.uniform(2.0, 2.05, 40), rng.uniform(-3.0, 9.0, 40), [np.nan]])
    off = np.array([0, 40, 81], dtype=np.int64)
    q = QUANTUM_SHARE * TOL
    codes, lo, step = encode_heights(off, h, q)
    e = np.repeat([0, 1], [40, 41])
    back = lo[e].astype(float) + step[e].astype(float) * codes
    ok = codes != NAN_CODE
    # the 0.05 mm edge is coded at the floor (within 1/1024 of it), the 12 mm edge as before
    assert q <= step[0] <= q * (1 + 1 / 1024) and step[1] > q
    assert np.abs(back - h)[ok].max() <= step.max() / 2 + 1e-9 and codes[~ok].tolist() == [NAN_CODE]
    assert int(codes[:40].max()) <= 0.05 / q + 1 and int(codes[:40].max()).bit_length() <= 10


def test_windowed_edges_force_the_full_sequences_break(tmp_path):
    f = SlopeWall()
    base = ZMap.from_function(f, (0, 0, 4, 4), 0.5)
    full = build_ez(base, f, tol=TOL, eps_r=0.0, prune=False, thin=False, verify=False,
                    se_curves=[np.array([[1.3, -1.0], [2.3, 5.0]])])
    ez = build_ez(base, f, tol=TOL, eps_r=0.0, prune=False, verify=False, se_curves=[np.array([[1.3, -1.0], [2.3, 5.0]])])
    kind0, t0 = full.breaks(base)
    kind, t = ez.breaks(base)
    w = np.flatnonzero(ez.win >= 0)
    assert w.size >= 8 and all(ez.window_break(int(k)) == kind0[k] for k in w)
    assert np.array_equal(kind[w], kind0[w]) and np.abs(t - t0)[w].max() * 50 <= 0.05
    # the slow reference forces them the same way
    m = 50
    exp = [ref.edge_break(ez, base, int(e), ez.tol, 4 * ez.tol / m, BREAK_RATIO) for e in ez.edge_ids]
    assert kind.tolist() == [k for k, _ in exp] and np.allclose(t, [x for _, x in exp], rtol=0, atol=1e-12)
    assert _k.WINDOW_HALF == WINDOW_HALF
    # format 5 keeps the forced kinds; format-4 arrays (16-bit codes, no kinds) still load,
    # their breaks searched for as before
    pm = PrecisionModel(base, ez=ez, meta={"method": "ez"})
    back = PrecisionModel.load(pm.save(tmp_path / "v5.zpm")).ez
    assert np.array_equal(back.win, ez.win) and np.array_equal(back.codes, ez.codes)
    a4 = {k: v for k, v in ez.to_arrays().items() if k not in ("codes_bits", "codes_w4", "win_kink")}
    a4 = a4 | {"version": np.array([4]), "codes": ez.codes}
    assert "patch_codes_bits" in a4 and ez.patches is None  # no patches: their codes are empty
    a4 = {k: v for k, v in a4.items() if not k.startswith("patch_codes")} | {
        "patch_codes": np.zeros(0, np.uint16), "patch_node_codes": np.zeros(0, np.uint16)}
    old = EZMap.from_arrays(a4)
    assert np.array_equal(old.win >= 0, ez.win >= 0) and old.window_break(int(w[0])) == 0
    assert np.array_equal(old.codes, ez.codes)
    x, y = np.random.default_rng(1).uniform(0, 4, (2, 20000))
    wall = np.abs(f.d(x, y)) < TOL
    assert np.abs(old.height(base, x, y) - f(x, y))[~wall].max() <= 2 * TOL


def test_patch_sub_edges_are_stored_as_differences_from_their_chords():
    from zmap.refine.patch import CellPatches

    from .test_patch import Rib

    rib = Rib()
    base = ZMap.from_function(rib, (0, 0, 4, 4), 0.5)
    p = build_ez(base, rib, tol=TOL).patches
    assert p is not None and (p.level > 0).sum() >= 2
    a = p.to_arrays()
    raw = np.unpackbits(a["codes_raw"], count=p.n_patches).astype(bool)
    assert not raw[p.level > 0].all()
    back = CellPatches.from_arrays(a)
    assert np.array_equal(back.codes, p.codes) and np.array_equal(back.nodes, p.nodes, equal_nan=True)
    # the first format-5 layout (every patch one plain segment, no raw bits) still loads,
    # and takes more bits
    nn, nc = np.diff(p.node_off), np.diff(p.code_off)
    seg = np.concatenate([[0], np.cumsum(nn + nc)]).astype(np.int64)
    allc = np.concatenate([np.concatenate([a_, b_]) for a_, b_ in zip(
        np.split(_node_codes(p), p.node_off[1:-1]), np.split(p.codes, p.code_off[1:-1]))]).astype(np.uint16)
    old = {k: v for k, v in a.items() if not k.startswith("codes_")} | {
        f"codes_{k}": v for k, v in pack_codes(allc, seg).items()}
    assert np.array_equal(CellPatches.from_arrays(old).codes, p.codes)
    assert a["codes_bits"].size < old["codes_bits"].size
    # a patch with a missing height stays plain (one segment), and still round-trips
    codes = p.codes.copy()
    k = int(np.flatnonzero(p.level > 0)[0])
    codes[p.code_off[k]] = NAN_CODE
    q = CellPatches(p.cells, p.level, p.node_off, p.nodes, p.code_off, codes, p.edge_off, p.lo, p.step, p.counts)
    b = q.to_arrays()
    assert np.unpackbits(b["codes_raw"], count=q.n_patches)[k] == 1
    assert np.array_equal(CellPatches.from_arrays(b).codes, codes)


def _node_codes(p):
    k = np.repeat(np.arange(p.n_patches), np.diff(p.node_off))
    lo, st = p.lo[p.edge_off[:-1]][k].astype(np.float64), p.step[p.edge_off[:-1]][k].astype(np.float64)
    return np.where(np.isnan(p.nodes), NAN_CODE, np.rint((np.nan_to_num(p.nodes) - lo) / st)).astype(np.uint16)


def test_sub_edge_counts_above_15_are_stored_in_the_bits_the_largest_needs_behind_a_bit():
    from zmap.refine._patches import _pack_counts, _unpack_counts

    c = np.array([0, 0, 17, 0, 3, 200, 0, 0, 0], dtype=np.uint16)
    a = _pack_counts(c)
    # 16, 2 and 199 (the counts less one) in 8 bits: 3 bytes
    assert set(a) == {"counts_nz", "counts_bw", "countsbnz"} and a["counts_bw"].tolist() == [8]
    assert a["countsbnz"].tolist() == [16, 2, 199] and np.array_equal(_unpack_counts(a, c.size), c)
    c24 = np.array([24, 0, 1, 17, 0, 9, 3], dtype=np.uint16)  # level 2 at grid 0.5: up to 24 points, 5 bits
    a = _pack_counts(c24)
    assert a["counts_bw"].tolist() == [5] and a["countsbnz"].size == 4  # 5 counts x 5 bits
    assert np.array_equal(_unpack_counts(a, c24.size), c24)
    # format 5 stored them a byte each
    old = {"counts_nz": np.packbits(c > 0), "counts8nz": np.array([17, 3, 200], dtype=np.uint8)}
    assert np.array_equal(_unpack_counts(old, c.size), c)
    a = _pack_counts(np.minimum(c, 15))
    assert set(a) == {"counts_nz", "counts4nz"} and np.array_equal(_unpack_counts(a, c.size), np.minimum(c, 15))
    assert set(_pack_counts(np.array([300, 0]))) == {"counts"}


def test_the_common_quantum_is_stored_once():
    from zmap.refine._ecodec import _pack_steps, _unpack_steps, half_step

    q = half_step(np.array([QUANTUM_SHARE * TOL]))[0]
    step = np.full(40, q, dtype=np.float32)
    step[[3, 17]] = half_step(np.array([1e-3, 2e-4]))
    a = _pack_steps(step)
    assert a["step"].size == 2 and a["step"].dtype == np.float16 and a["step_common"].tolist() == [q]
    assert np.array_equal(_unpack_steps(a, 40), step)
    # all different (or few): stored as they are
    few = half_step(np.linspace(1e-4, 1e-3, 20))
    assert set(_pack_steps(few)) == {"step"} and np.array_equal(_unpack_steps(_pack_steps(few), 20), few)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.lists(st.one_of(st.floats(-40.0, 60.0), st.just(float("nan"))), min_size=1, max_size=8),
                min_size=1, max_size=40),
       st.sampled_from([QUANTUM_SHARE * TOL, 0.01 / 32, 1e-3]))
def test_offsets_lie_on_the_quantum_lattice_and_round_trip(segments, quantum):
    h = np.array([v for s in segments for v in s])
    off = np.concatenate([[0], np.cumsum([len(s) for s in segments])]).astype(np.int64)
    codes, lo, step = encode_heights(off, h, quantum)
    # every offset at or below its edge's lowest height, the codes within half a quantum
    e = np.repeat(np.arange(len(segments)), np.diff(off))
    fin = ~np.isnan(h)
    assert np.all(lo[e][fin].astype(np.float64) <= h[fin])
    dec = lo[e].astype(np.float64) + step[e].astype(np.float64) * codes
    assert np.all(np.abs(dec[fin] - h[fin]) <= 0.5 * step[e][fin] * (1 + 1e-6) + 1e-9)
    assert np.all(codes[~fin] == NAN_CODE) and np.all(codes[fin] < NAN_CODE)
    a = pack_offsets(lo, quantum)
    back = unpack_offsets(a, lo.size)
    assert back.dtype == np.float32 and np.array_equal(back, lo)
    if lo.size >= 8 and fin.any():
        # steps of the quantum above the lowest offset, in the bits the largest needs
        k = np.rint((lo.astype(np.float64) - float(lo.min())) / quantum).astype(np.int64)
        assert "lo" not in a and a["lo_k"].size == (lo.size * max(1, int(k.max()).bit_length()) + 7) // 8


def test_offsets_off_the_lattice_are_stored_as_float32():
    lo = np.array([0.0, 0.1, 0.25, 1.0 / 3.0, 2.0, 7.5, 9.1, 12.0], dtype=np.float32)
    a = pack_offsets(lo, QUANTUM_SHARE * TOL)
    assert set(a) == {"lo"} and np.array_equal(unpack_offsets(a, lo.size), lo)
