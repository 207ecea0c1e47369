"""The icosahedral direction set: O(1) lookup against brute force, nesting, bitsets."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zmap.access.directions import DirectionSet, count, direction_set, from_bool, to_bool

# one xdist worker compiles this family's numba kernels once (tests/conftest.py)
pytestmark = pytest.mark.xdist_group("access")


@pytest.mark.parametrize("q", [1, 2, 3, 4, 7])
def test_counts_and_solid_angles(q):
    ds = DirectionSet(q)
    assert ds.k == 20 * q * q and ds.normals.shape == (ds.k, 3)
    assert ds.words == (ds.k + 63) // 64
    np.testing.assert_allclose(ds.area.sum(), 4 * np.pi, rtol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(ds.normals, axis=1), 1.0)
    # every normal is inside its own tessel's patch and found there
    assert ds.contains(np.arange(ds.k), ds.normals).all()
    assert (ds.lookup(ds.normals) == np.arange(ds.k)).all()


@pytest.mark.parametrize("q", [1, 2, 4, 5])
def test_lookup_agrees_with_brute_force_containment(q):
    ds = DirectionSet(q)
    rng = np.random.default_rng(11)
    n = rng.normal(size=(50_000, 3))
    t = ds.lookup(n)
    assert ((t >= 0) & (t < ds.k)).all()
    assert ds.contains(t, n / np.linalg.norm(n, axis=1)[:, None]).all()
    # the icosahedron's own vertices and edge midpoints (ties) land in a tessel touching them
    v = ds.vertices.reshape(-1, 3)
    tv = ds.lookup(v)
    assert ds.contains(tv, v).all()


def test_lookup_of_bad_directions():
    ds = direction_set(2)
    assert ds.lookup([[0.0, 0.0, 0.0], [np.nan, 0, 1]]).tolist() == [-1, -1]
    with pytest.raises(ValueError, match="shape"):
        ds.lookup([1.0, 2.0])


@pytest.mark.parametrize("q", [0, -3, 1.5, "4", True])
def test_bad_q(q):
    with pytest.raises(ValueError, match="q must be an integer >= 1"):
        DirectionSet(q)


@pytest.mark.parametrize("q1,m", [(1, 2), (2, 2), (1, 4), (3, 2)])
def test_larger_q_refines_smaller(q1, m):
    """Each tessel of frequency m*q lies inside one tessel of frequency q."""
    coarse, fine = DirectionSet(q1), DirectionSet(m * q1)
    parent = coarse.lookup(fine.normals)
    # all three vertices of the fine tessel, pulled a hair toward its centre, in the parent
    v = fine.vertices
    inner = v + 1e-9 * (fine.normals[:, None, :] - v)
    for j in range(3):
        assert coarse.contains(parent, inner[:, j]).all()
    # every coarse tessel is split into exactly m^2 fine ones
    assert np.bincount(parent, minlength=coarse.k).tolist() == [m * m] * coarse.k


def test_hemisphere_bitsets_are_the_paper_sets():
    ds = DirectionSet(3)
    hv = to_bool(ds.hv, ds.k)
    hl = to_bool(ds.hl, ds.k)
    for t in (0, 17, 101, ds.k - 1):
        d = ds.normals @ ds.vertices[t].T  # (k, 3)
        assert (hv[t] == (d > 0).all(axis=1)).all()
        assert (hl[t] == (d > 0).any(axis=1)).all()
    # H_V(t) never holds a direction some normal of the tessel does not see: conservative
    rng = np.random.default_rng(3)
    n = rng.normal(size=(5000, 3))
    n /= np.linalg.norm(n, axis=1)[:, None]
    t = ds.lookup(n)
    exact = n @ ds.normals.T > 0
    assert not (hv[t] & ~exact).any()
    assert not (exact & ~hl[t]).any()


@settings(max_examples=40, deadline=None)
@given(st.lists(st.lists(st.booleans(), min_size=130, max_size=130), min_size=1, max_size=5))
@pytest.mark.slow
def test_bitset_round_trip(rows):
    mask = np.array(rows, dtype=bool)
    bits = from_bool(mask)
    assert bits.shape == (len(rows), 3) and bits.dtype == np.uint64
    assert (to_bool(bits, 130) == mask).all()
    assert (count(bits) == mask.sum(axis=1)).all()


def test_hemisphere_of_plus_z():
    ds = DirectionSet(4)
    h = to_bool(ds.hemisphere([0.0, 0.0, 1.0]), ds.k)
    assert (h == (ds.normals[:, 2] > 0)).all()
    assert ds.index("+z") == int(ds.lookup([0, 0, 1.0]))
    with pytest.raises(ValueError, match="not one of"):
        ds.index("up")


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), q=st.integers(1, 4), jitter=st.sampled_from([0.0, 1e-15, 1e-9, 1e-4, 0.05]))
def test_folded_hemispheres_equal_the_direct_ones(seed, q, jitter):
    """``piece_accumulate`` (exact) keeps the last hemisphere while the normals stay within its
    margin; its V'_l (AND) and L' (OR) per piece equal those of every sample's hemisphere made
    directly, for runs of equal, nearly equal and scattered normals, and for normals that
    graze a direction of the set."""
    from zmap.access._access_kernels import piece_accumulate

    ds = direction_set(q)
    rng = np.random.default_rng(seed)
    base = rng.normal(size=(12, 3))
    # one run in three starts on a direction's great circle: a dot product of 0 there
    for r in range(0, 12, 3):
        d = ds.normals[rng.integers(ds.k)]
        base[r] -= (base[r] @ d) * d
    base /= np.linalg.norm(base, axis=1)[:, None]
    nrm = np.repeat(base, 20, axis=0) + jitter * rng.normal(size=(240, 3))
    nrm /= np.linalg.norm(nrm, axis=1)[:, None]
    piece = np.sort(rng.integers(0, 5, size=240))
    pts = rng.normal(size=(240, 3))
    W = ds.words
    vl = np.full((5, W), np.uint64(0xFFFFFFFFFFFFFFFF), dtype=np.uint64)
    light = np.zeros((5, W), dtype=np.uint64)
    z3, lo, hi = np.zeros((5, 3)), np.full((5, 3), np.inf), np.full((5, 3), -np.inf)
    piece_accumulate(piece, pts, nrm, ds._centres, ds._frames, ds.q, ds.hv, ds.hl, 1, ds.normals, vl, light,
                     z3.copy(), z3.copy(), lo, hi)
    D = ds.normals
    # the dot products in the kernel's order (a matrix product may sum otherwise, and the
    # grazing normals sit on a sign)
    dots = nrm[:, 0, None] * D[None, :, 0] + nrm[:, 1, None] * D[None, :, 1] + nrm[:, 2, None] * D[None, :, 2]
    above = from_bool(dots > 0.0)
    k_mask = from_bool(np.ones((1, ds.k), dtype=bool))[0]
    for p in range(5):
        mine = above[piece == p]
        want_vl = np.bitwise_and.reduce(mine, axis=0) if len(mine) else vl[p]
        want_l = np.bitwise_or.reduce(mine, axis=0) if len(mine) else light[p]
        assert np.array_equal(vl[p] & k_mask, want_vl & k_mask)
        assert np.array_equal(light[p], want_l)


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), floor=st.sampled_from([-0.05, 0.0, 0.5]))
def test_above_bits_are_the_directions_over_the_floor(seed, floor):
    from zmap.access._direction_kernels import above_bits

    ds = direction_set(3)
    n = np.random.default_rng(seed).normal(size=(50, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    out = np.empty((len(n), ds.words), dtype=np.uint64)
    above_bits(np.ascontiguousarray(ds.normals), n, floor, out)
    dots = np.array([[d[0] * m[0] + d[1] * m[1] + d[2] * m[2] for d in ds.normals] for m in n])
    assert (to_bool(out, ds.k) == (dots > floor)).all()
