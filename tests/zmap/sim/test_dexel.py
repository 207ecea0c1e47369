"""Dexel and height-field workpieces against the plain-Python reference."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from zmap.grid import ZMap
from tests.reference.sim import cut_reference, dexel_lists, heightfield_reference
from zmap.sim.dexel import DexelWorkpiece
from zmap.sim.heightfield import HeightField, cut_heightfield
from zmap.sim.tools import Cutter

SETTINGS = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@st.composite
def cutters(draw):
    kind = draw(st.sampled_from(["flat", "ball", "bull"]))
    d = draw(st.floats(0.4, 3.0))
    length = draw(st.floats(0.3, 4.0))
    if kind == "bull":
        rc = draw(st.floats(0.05, 1.0)) * d / 2
        return Cutter("bull", d, rc, max(length, rc))
    if kind == "ball":
        return Cutter("ball", d, 0.0, max(length, d / 2))
    return Cutter("flat", d, 0.0, length)


@st.composite
def cut_cases(draw, n_max=25):
    """A small box stock, 1-2 cutters and tool positions inside/around it."""
    pitch = draw(st.sampled_from([0.25, 0.3, 0.5]))
    x1 = draw(st.floats(1.0, 3.0))
    y1 = draw(st.floats(1.0, 3.0))
    bounds = (0.0, 0.0, -3.0, x1, y1, 0.0)
    cs = draw(st.lists(cutters(), min_size=1, max_size=2))
    n = draw(st.integers(1, n_max))
    seed = draw(st.integers(0, 2**31))
    rng = np.random.default_rng(seed)
    xyz = np.column_stack([rng.uniform(-0.5, x1 + 0.5, n), rng.uniform(-0.5, y1 + 0.5, n),
                           rng.uniform(-4.0, 0.5, n)])
    # some positions on ray lines and on exact ray distances to hit the boundary cases
    xyz[::3, 0] = np.round(xyz[::3, 0] / pitch) * pitch
    slot = rng.integers(0, len(cs), n).astype(np.int32)
    return bounds, pitch, cs, xyz, slot


@SETTINGS
@given(cut_cases())
def test_dexels_equal_bruteforce_reference(case):
    bounds, pitch, cs, xyz, slot = case
    wp = DexelWorkpiece.from_box(bounds, pitch=pitch)
    ref = cut_reference(dexel_lists(wp), wp.x0, wp.y0, wp.pitch, wp.nx, wp.ny, xyz, cs, slot)
    wp.cut(xyz, cs, slot)
    assert dexel_lists(wp) == ref


@SETTINGS
@given(cut_cases())
def test_cutting_never_adds_material(case):
    bounds, pitch, cs, xyz, slot = case
    wp = DexelWorkpiece.from_box(bounds, pitch=pitch)
    for p in range(len(xyz)):
        before = dexel_lists(wp)
        wp.cut(xyz[p:p + 1], cs, slot[p:p + 1])
        after = dexel_lists(wp)
        for old, new in zip(before, after):
            # every new dexel lies inside one old dexel; intervals stay sorted and disjoint
            for n, f in new:
                assert n < f
                assert any(on <= n and f <= of for on, of in old)
            for (n0, f0), (n1, f1) in zip(new, new[1:]):
                assert f0 < n1
        top_b = np.array([v[-1][1] if v else -np.inf for v in before])
        top_a = np.array([v[-1][1] if v else -np.inf for v in after])
        assert (top_a <= top_b).all()


def test_four_cases_and_counts():
    """Split, delete, shorten front, shorten back on one ray, counted."""
    wp = DexelWorkpiece.from_box((0, 0, -10, 0.1, 0.1, 0), pitch=1.0)  # a single ray at (0, 0)
    flat_short = Cutter("flat", 0.5, 0.0, 2.0)
    wp.cut(np.array([[0.0, 0.0, -6.0]]), flat_short)       # tool [-6, -4] inside: split
    assert wp.intervals(0, 0).tolist() == [[-10, -6], [-4, 0]] and wp.created == 1
    wp.cut(np.array([[0.0, 0.0, -1.0]]), flat_short)       # tool [-1, 1]: shorten back of the top
    assert wp.intervals(0, 0).tolist() == [[-10, -6], [-4, -1]]
    wp.cut(np.array([[0.0, 0.0, -11.0]]), Cutter("flat", 0.5, 0.0, 3.0))  # [-11, -8]: shorten front
    assert wp.intervals(0, 0).tolist() == [[-8, -6], [-4, -1]]
    wp.cut(np.array([[0.0, 0.0, -4.5]]), Cutter("flat", 0.5, 0.0, 4.0))   # [-4.5, -0.5]: delete top
    assert wp.intervals(0, 0).tolist() == [[-8, -6]] and wp.deleted == 1
    assert np.isclose(wp.top()[0, 0], -6.0)


def test_many_splits_grow_slots():
    wp = DexelWorkpiece.from_box((0, 0, -20, 0.1, 0.1, 0), pitch=1.0)
    c = Cutter("flat", 0.5, 0.0, 0.5)
    tips = np.array([[0.0, 0.0, -1.0 - 2.0 * k] for k in range(9)])
    wp.cut(tips, c)
    assert wp.cnt[0] == 10 and wp.slots >= 10 and wp.created == 9


def test_from_zmap_stock_and_holes():
    z = np.array([[0.0, 1.0, np.nan], [2.0, 3.0, 4.0]])
    zm = ZMap(0.0, 0.0, 0.5, 0.5, z)
    wp = DexelWorkpiece.from_zmap(zm, bottom=-1.0)
    assert wp.shape == (2, 3)
    assert wp.intervals(1, 2).tolist() == [[-1.0, 4.0]]
    assert wp.intervals(0, 2).shape == (0, 2)
    top = wp.top()
    assert np.isnan(top[0, 2]) and top[1, 1] == 3.0
    fine = DexelWorkpiece.from_zmap(zm, pitch=0.25, bottom=-1.0)
    assert fine.shape == (3, 5) and np.isclose(fine.top()[1, 1], 1.5)


def test_bad_stock_inputs():
    with pytest.raises(ValueError, match="x0 < x1"):
        DexelWorkpiece.from_box((0, 0, 0, -1, 1, 1))
    with pytest.raises(ValueError, match="6 finite numbers"):
        DexelWorkpiece.from_box((0, 0, 1))
    with pytest.raises(ValueError, match="pitch"):
        DexelWorkpiece.from_box((0, 0, 0, 1, 1, 1), pitch=0)
    with pytest.raises(ValueError, match="no surface"):
        DexelWorkpiece.from_zmap(ZMap(0, 0, 1, 1, np.full((2, 2), np.nan)))


@SETTINGS
@given(cut_cases(n_max=15))
@pytest.mark.slow
def test_heightfield_matches_reference_and_dexel_top(case):
    bounds, pitch, cs, xyz, slot = case
    c = cs[0]
    xyz = xyz.copy()
    xyz[:, 2] = np.maximum(xyz[:, 2], -2.5)  # stay above the stock bottom: no holes through it
    c = Cutter(c.kind, c.diameter, c.corner_radius, 10.0)  # long enough to reach above the stock
    nx = int(np.floor(bounds[3] / pitch + 1e-9)) + 1
    ny = int(np.floor(bounds[4] / pitch + 1e-9)) + 1
    zm = ZMap(0.0, 0.0, pitch, pitch, np.zeros((nx, ny)))
    hf = cut_heightfield(zm, xyz, c)
    ref = heightfield_reference(zm.z, 0.0, 0.0, pitch, pitch, xyz, c)
    assert np.array_equal(hf.z, ref)
    assert (hf.z <= zm.z).all()
    wp = DexelWorkpiece.from_box(bounds, pitch=pitch).cut(xyz, c)
    assert np.allclose(wp.top(), hf.z, atol=1e-5)


def test_heightfield_rejects_nan_positions():
    with pytest.raises(ValueError, match="NaN"):
        HeightField(ZMap(0, 0, 1, 1, np.zeros((2, 2)))).cut(np.array([[np.nan, 0, 0]]), Cutter("flat", 1))


@settings(max_examples=30, deadline=None, derandomize=True)
@given(st.integers(1, 7), st.integers(1, 7), st.integers(0, 6), st.integers(0, 2**31 - 1))
def test_csr_round_trip_and_tile_scatter_agree_with_numpy(nx, ny, kmax, seed):
    """``to_csr``/``from_csr`` (numba) against the boolean-mask form, and a stock scattered back
    from row subsets (as the tiled run assembles its tiles) equal to the stock."""
    from zmap.sim import _csr_kernels

    rng = np.random.default_rng(seed)
    n = nx * ny
    cnt = rng.integers(0, kmax + 1, n).astype(np.int32)
    slots = max(4, kmax)
    near = rng.normal(size=(n, slots)).astype(np.float32)
    far = rng.normal(size=(n, slots)).astype(np.float32)
    wp = DexelWorkpiece(0.0, 0.0, 0.5, nx, ny, near, far, cnt)
    off, cn, cf = wp.to_csr()
    mask = np.arange(slots)[None, :] < cnt[:, None]
    assert np.array_equal(off, np.concatenate([[0], np.cumsum(cnt)]))
    assert np.array_equal(cn, near[mask]) and np.array_equal(cf, far[mask])
    back = DexelWorkpiece.from_csr(0.0, 0.0, 0.5, nx, ny, off, cn, cf)
    assert back.same_as(wp) and np.array_equal(back.cnt, cnt)
    # two interleaved subsets of rays, each as its own lists, scattered into one stock
    out_n = np.zeros((n, slots), dtype=np.float32)
    out_f = np.zeros((n, slots), dtype=np.float32)
    out_c = np.zeros(n, dtype=np.int32)
    for rows in (np.arange(0, n, 2), np.arange(1, n, 2)):
        sub_off = np.concatenate([[0], np.cumsum(cnt[rows])]).astype(np.int64)
        m = mask[rows]
        _csr_kernels.scatter(rows.astype(np.int64), sub_off, near[rows][m], far[rows][m], out_n, out_f, out_c)
    assert DexelWorkpiece(0.0, 0.0, 0.5, nx, ny, out_n, out_f, out_c).same_as(wp)


def test_from_csr_refuses_offsets_of_another_stock():
    with pytest.raises(ValueError, match="offsets has shape"):
        DexelWorkpiece.from_csr(0.0, 0.0, 0.5, 3, 3, np.zeros(5, dtype=np.int64), np.zeros(0), np.zeros(0))
