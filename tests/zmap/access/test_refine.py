"""The refinement of the casting (``global_visibility(refine=True)``): half-voxel pieces cast
with a thinner cylinder where the voxel's is blocked. Against the pair-by-pair reference, and on
a hemispherical cavity against the closed-form thin rays from every sample."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import zmap.access.casting as V
from tests.reference.access import global_visibility_reference
from zmap.access.directions import count, to_bool
from zmap.access.voxelmap import VoxelMap, global_visibility

from .test_voxelmap import bowl_samples, box_samples

# one xdist worker compiles this family's numba kernels once (tests/conftest.py)
pytestmark = pytest.mark.xdist_group("access")


def bowl_hit(p, n, r):
    """Closed form for the cavity of :func:`bowl_samples` (radius r at the origin, top z = 0):
    distance along n from the cavity point p to where the thin ray meets the part (inf: free).
    The ray crosses the cavity's chord to the sphere at t* = -2 p.n; it leaves through the
    opening when it reaches z = 0 first (n_z > 0), else it meets the sphere at t*."""
    p = np.atleast_2d(p)
    n = np.atleast_2d(n)
    pn = p @ n.T  # (points, directions)
    tstar = -2.0 * pn
    nz = n[:, 2][None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        ttop = np.where(nz > 0, -p[:, 2][:, None] / np.where(nz > 0, nz, 1.0), np.inf)
    free = (nz > 0) & (ttop <= tstar)
    return np.where(free, np.inf, np.maximum(tstar, 0.0))


def _parents(vm, vb, pb):
    f = vm.fine
    parent = vb[f.voxel].copy()
    pi = V._piece_index(vm, f.voxel, f.face)
    parent[pi >= 0] = pb[pi[pi >= 0]]
    return parent


@pytest.fixture(scope="module")
def small_bowl():
    return VoxelMap.from_samples(*bowl_samples(r=2.0, half=3.0, depth=2.5, step=0.15), d=0.6, q=1, step=0.15)


@pytest.fixture(scope="module")
def bowl3():
    P, N, K, F, W = bowl_samples(r=3.0, half=4.0, depth=3.5, step=0.1)
    vm = VoxelMap.from_samples(P, N, K, F, W, d=0.5, q=3, step=0.1)
    return vm, (P, N, F)


def test_fine_pieces_partition_the_samples(bowl3):
    """One half-voxel piece per face and half-voxel cell; its box holds its samples, inside its
    cell, and its V'_l is the AND of their hemispheres (a superset of its voxel's)."""
    vm, (P, N, F) = bowl3
    f = vm.fine
    keys = (f.voxel * 8 + f.octant) * (int(F.max()) + 1) + f.face
    assert (np.diff(keys) > 0).all()  # sorted and unique
    v = vm.voxel_of(P)
    half = np.clip(np.floor(2 * (P - vm.origin) / vm.d).astype(int) - 2 * vm.ijk[v], 0, 1)
    oc = (half[:, 0] * 2 + half[:, 1]) * 2 + half[:, 2]
    at = np.searchsorted(keys, (v * 8 + oc) * (int(F.max()) + 1) + F)
    assert (keys[at] == (v * 8 + oc) * (int(F.max()) + 1) + F).all()
    assert (P >= f.lo[at] - 1e-9).all() and (P <= f.hi[at] + 1e-9).all()
    cell_lo = vm.origin + vm.d * vm.ijk[f.voxel] + 0.5 * vm.d * np.stack(
        [f.octant // 4, (f.octant // 2) % 2, f.octant % 2], axis=1)
    assert (f.lo >= cell_lo - 1e-12).all() and (f.hi <= cell_lo + 0.5 * vm.d + 1e-12).all()
    assert not (vm.vl[f.voxel] & ~f.vl).any()
    ds = vm.directions
    j = at[:: max(1, len(at) // 300)]
    hemi = (N[:: max(1, len(at) // 300)] @ ds.normals.T) > 0
    assert not (to_bool(f.vl[j], ds.k) & ~hemi).any()


@pytest.mark.slow
def test_fine_cast_matches_the_reference_on_a_bowl(small_bowl, monkeypatch):
    """The refinement's cast (half the pitch, only the lost directions, tiles) gives the bits
    of the plain reference casting each half-voxel piece on its own; voxels and pieces keep
    what all their half-voxel pieces keep."""
    vm = small_bowl
    monkeypatch.setattr(V, "_REFINE_NEAR", -1)  # every lost direction
    vb0, pb0 = global_visibility(vm, pieces=True)
    vb, pb, fb = global_visibility(vm, pieces=True, refine=True)
    parent = _parents(vm, vb0, pb0)
    ref = global_visibility_reference(vm, rays=4, fine=True)
    # the bowl's floor (0.5 mm) is thinner than the voxel: its uncertain voxels are not refined
    unc = vm.uncertain[vm.fine.voxel]
    assert unc.any() and (fb[unc] == parent[unc]).all()
    assert (fb[~unc] == (parent | ref)[~unc]).all()
    assert (fb & ~parent).any()  # it frees something here
    f = vm.fine
    for b in range(vm.n_boundary):
        mine = f.voxel == b
        assert (vb[b] == (vb0[b] | np.bitwise_and.reduce(fb[mine], axis=0))).all()
    for j in range(len(vm.pieces.voxel)):
        mine = (f.voxel == vm.pieces.voxel[j]) & (f.face == vm.pieces.face[j])
        assert (pb[j] == (pb0[j] | np.bitwise_and.reduce(fb[mine], axis=0))).all()


def test_tiles_and_the_near_filter_only_skip_work(small_bowl, monkeypatch):
    """Drawing only over the tiles under a query gives the same bits; the filter near a shadow
    edge casts a subset of the pairs, so its bits lie between the unrefined and the full ones."""
    vm = small_bowl
    cast = V._casting(vm)
    qx, qh = V._query_boxes(vm, fine=True)
    f = vm.fine
    args = (qx, qh, -3 - np.arange(len(qx)), np.zeros_like(f.vl), f.vl, f.point, f.normal, f.slab, vm.d / 4)
    plain_fine = V._cast(vm, cast, *args, tile=0)
    assert (plain_fine == V._cast(vm, cast, *args, tile=3)).all()
    assert (plain_fine == V._cast(vm, cast, *args, tile=3, lists=True)).all()
    assert (plain_fine == V._cast(vm, cast, *args, lists=True)).all()
    plain = global_visibility(vm, pieces=True)
    monkeypatch.setattr(V, "_TILE", 2)  # the voxels' cast with tiles too
    assert all((a == b).all() for a, b in zip(plain, global_visibility(vm, pieces=True)))
    monkeypatch.setattr(V, "_TILE", 0)
    vb0, pb0 = global_visibility(vm, pieces=True)
    monkeypatch.setattr(V, "_REFINE_NEAR", -1)
    full = global_visibility(vm, pieces=True, refine=True)
    monkeypatch.setattr(V, "_REFINE_NEAR", 0)
    near = global_visibility(vm, pieces=True, refine=True)
    for a, b, c in zip((vb0, pb0, _parents(vm, vb0, pb0)), near, full):
        assert not (a & ~b).any() and not (b & ~c).any()


def test_bit_lists_are_the_rows_of_each_direction():
    from zmap.access._access_kernels import bit_lists

    rng = np.random.default_rng(4)
    bits = rng.integers(0, 2**63, size=(50, 2), dtype=np.int64).view(np.uint64)
    bits[rng.random(50) < 0.3] = 0
    k = 100
    bits[:, 1] &= np.uint64((1 << (k - 64)) - 1)
    ptr = np.zeros(k + 1, dtype=np.int64)
    idx = np.empty(int(count(bits).sum()), dtype=np.int64)
    bit_lists(bits, k, ptr, idx)
    dense = to_bool(bits, k)
    for i in range(k):
        assert (idx[ptr[i]:ptr[i + 1]] == np.flatnonzero(dense[:, i])).all()


def test_dilated_bits_are_the_or_over_the_neighbours(small_bowl):
    from zmap.access._access_kernels import dilate_bits

    vm = small_bowl
    rng = np.random.default_rng(2)
    bits = rng.integers(0, 2**63, size=(vm.n_boundary, 2), dtype=np.int64).view(np.uint64)
    bits[rng.random(vm.n_boundary) < 0.7] = 0
    out = np.empty_like(bits)
    dilate_bits(vm.index, vm.ijk.astype(np.int64), bits, 1, out)
    for b in rng.choice(vm.n_boundary, 60, replace=False):
        near = np.flatnonzero(np.abs(vm.ijk - vm.ijk[b]).max(axis=1) <= 1)
        assert (out[b] == np.bitwise_or.reduce(bits[near], axis=0)).all()


def test_refinement_frees_what_every_ray_of_the_piece_frees_on_a_bowl(bowl3):
    """A hemispherical cavity: the refinement frees (half-voxel piece, direction) pairs that the
    voxel-wide cylinder blocks although the thin ray from every sample of the piece leaves the
    cavity (closed form), agrees with the closed form on more pairs, and stays conservative:
    no kept direction of a piece, nor of a voxel, is blocked within the part farther than a
    voxel diagonal from any of its samples."""
    vm, (P, N, F) = bowl3
    ds = vm.directions
    vb0, pb0 = global_visibility(vm, pieces=True)
    vb, pb, fb = global_visibility(vm, pieces=True, refine=True)
    f = vm.fine
    parent = _parents(vm, vb0, pb0)
    nf = int(F.max()) + 1
    v = vm.voxel_of(P)
    half = np.clip(np.floor(2 * (P - vm.origin) / vm.d).astype(int) - 2 * vm.ijk[v], 0, 1)
    at = np.searchsorted((f.voxel * 8 + f.octant) * nf + f.face,
                         (v * 8 + (half[:, 0] * 2 + half[:, 1]) * 2 + half[:, 2]) * nf + F)
    cav = F == 6
    hit = bowl_hit(P[cav], ds.normals, 3.0)  # (cavity samples, k)
    diag = np.sqrt(3.0) * vm.d
    # per half-voxel piece of the cavity: every sample's ray free / the nearest far block
    pc = at[cav]
    order = np.argsort(pc, kind="stable")
    start = np.flatnonzero(np.r_[True, np.diff(pc[order]) != 0])
    ids = pc[order][start]
    all_free = np.logical_and.reduceat(np.isinf(hit[order]), start, axis=0)
    far_block = np.logical_or.reduceat(np.isfinite(hit[order]) & (hit[order] > diag), start, axis=0)
    old = to_bool(parent[ids], ds.k)
    new = to_bool(fb[ids], ds.k)
    freed = new & ~old
    assert freed.sum() > 50
    assert (freed & all_free).sum() > 0.9 * freed.sum()
    assert not (new & far_block).any() and not (old & far_block).any()
    assert (new == all_free).sum() > (old == all_free).sum()
    # the voxels' lifted bits: every sample of the voxel
    vc = v[cav]
    order = np.argsort(vc, kind="stable")
    start = np.flatnonzero(np.r_[True, np.diff(vc[order]) != 0])
    far_v = np.logical_or.reduceat(np.isfinite(hit[order]) & (hit[order] > diag), start, axis=0)
    kept = to_bool(vb[vc[order][start]], ds.k)
    assert not (kept & far_v).any()
    assert (count(vb) >= count(vb0)).all() and (count(vb) > count(vb0)).any()


def _strict_refinement(vm):
    """``global_visibility(vm, pieces=True, refine=True)`` with ``_FINE_STRICT`` on."""
    old, V._FINE_STRICT = V._FINE_STRICT, 1
    try:
        return global_visibility(vm, pieces=True, refine=True)
    finally:
        V._FINE_STRICT = old


def _cavity_pieces(vm, P, F):
    """The cavity's samples (face 6), their voxels and the index of each one's half-voxel piece."""
    f = vm.fine
    cav = np.flatnonzero(F == 6)
    v = vm.voxel_of(P[cav])
    nf = int(F.max()) + 1
    half = np.clip(np.floor(2 * (P[cav] - vm.origin) / vm.d).astype(int) - 2 * vm.ijk[v], 0, 1)
    at = np.searchsorted((f.voxel * 8 + f.octant) * nf + f.face,
                         (v * 8 + (half[:, 0] * 2 + half[:, 1]) * 2 + half[:, 2]) * nf + F[cav])
    return cav, v, at


@pytest.mark.xfail(strict=True, reason="known defect: on this cavity, with its samples on voxel "
                   "boundaries, the strict cast adds a direction blocked beyond a voxel diagonal")
def test_strict_refinement_far_miss_on_a_bowl_on_voxel_boundaries():
    """A counterexample hypothesis found (shift (0, -1e-5, 0), r = 2.328125), kept so that
    its fix shows: the test below draws its cases from a fixed seed."""
    _check_strict_refinement((0.0, -1e-05, 0.0), 2.328125)


# derandomized: a fresh random draw found the case above, and CI must not fail at random
@settings(max_examples=8, deadline=None, derandomize=True)
@given(shift=st.tuples(*[st.floats(-0.3, 0.3, allow_nan=False)] * 3), r=st.floats(1.6, 2.4))
@pytest.mark.slow
def test_strict_refinement_adds_no_far_miss_on_shifted_bowls(shift, r):
    _check_strict_refinement(shift, r)


def _check_strict_refinement(shift, r):
    """Whatever the cavity's place in the voxel grid and its radius: the refined pieces keep
    every direction their voxel or piece keeps and none outside their V'_l; cast strictly
    (every cell under the piece's box, from the lowest start of a ray of the cell) they add no
    direction that the closed form finds blocked farther than a voxel diagonal from one of
    their samples, beyond those the voxels' own cast already keeps (the paper's casting,
    lines through cell centres, keeps such a pair on some cavities: r = 1.707, shift
    (-0.06, -0.18, -0.14) is one)."""
    P, N, K, F, W = bowl_samples(r=r, half=3.0, depth=2.6, step=0.12)
    P = P + np.asarray(shift)
    # the casting's own answers: without the uncertain voxels of the cavity's thin floor and
    # walls (0.3-0.7 mm at d = 0.5), which would block the rays in question as whole cubes
    vm = VoxelMap.from_samples(P, N, K, F, W, d=0.5, q=2, step=0.12, check=False)
    ds = vm.directions
    vb0, pb0 = global_visibility(vm, pieces=True)
    vb, pb, fb = global_visibility(vm, pieces=True, refine=True)
    f = vm.fine
    parent = _parents(vm, vb0, pb0)
    assert not (parent & ~fb).any() and not (fb & ~(f.vl | parent)).any()
    assert not (vb0 & ~vb).any() and not (vb & ~vm.vl).any()
    vbs, pbs, fbs = _strict_refinement(vm)
    assert not (parent & ~fbs).any() and not (fbs & ~(f.vl | parent)).any()
    cav, v, at = _cavity_pieces(vm, P, F)
    hit = bowl_hit(P[cav] - np.asarray(shift), ds.normals, r)
    far = np.isfinite(hit) & (hit > np.sqrt(3.0) * vm.d)
    assert not (to_bool(fbs[at] & ~parent[at], ds.k) & far).any()
    assert not (to_bool(vbs[v] & ~vb0[v], ds.k) & far).any()


def test_default_refinement_misses_on_a_cavity_that_strict_catches():
    """The known limit of the default refinement (lines through cell centres, as the paper's
    casting): on this cavity a half-voxel piece keeps a direction whose ray from two of its
    samples passes 0.007 mm under the far rim (blocked 3.2 mm away); the voxels' cast and the
    strict refinement do not keep it."""
    r = 1.8125
    P, N, K, F, W = bowl_samples(r=r, half=3.0, depth=2.6, step=0.12)
    vm = VoxelMap.from_samples(P, N, K, F, W, d=0.5, q=2, step=0.12, check=False)  # the casting alone, as above
    ds = vm.directions
    vb0, pb0 = global_visibility(vm, pieces=True)
    parent = _parents(vm, vb0, pb0)
    fb = global_visibility(vm, pieces=True, refine=True)[2]
    fbs = _strict_refinement(vm)[2]
    cav, v, at = _cavity_pieces(vm, P, F)
    hit = bowl_hit(P[cav], ds.normals, r)
    far = np.isfinite(hit) & (hit > np.sqrt(3.0) * vm.d)
    assert (to_bool(fb[at], ds.k) & far).sum() == 2
    assert not (to_bool(fbs[at], ds.k) & far).any() and not (to_bool(parent[at], ds.k) & far).any()


def test_bitsets_folded_from_the_fine_pieces_are_the_samples(bowl3):
    """With half-voxel pieces the voxels' and pieces' V'_l and L' are folded from theirs: the
    same bits as folding the samples directly (``fine=False``)."""
    vm, _ = bowl3
    P, N, K, F, W = bowl_samples(r=3.0, half=4.0, depth=3.5, step=0.1)
    bare = VoxelMap.from_samples(P, N, K, F, W, d=0.5, q=3, step=0.1, fine=False)
    for a, b in ((vm.vl, bare.vl), (vm.light, bare.light), (vm.pieces.vl, bare.pieces.vl),
                 (vm.pieces.light, bare.pieces.light)):
        assert (a == b).all()


def test_convex_box_gains_directions_and_no_fine_map_without_refine():
    """On a convex box every direction of a face's hemisphere is free: the refinement only
    brings the map closer to that; ``fine=False`` builds no half-voxel pieces and
    ``refine=True`` then leaves the bits as they were."""
    args = box_samples(np.array([0.1, 0.2, 0.3]), np.array([3.1, 2.7, 2.3]), 0.125)
    vm = VoxelMap.from_samples(*args, d=0.5, q=2, step=0.125)
    vb0 = global_visibility(vm)
    vb = global_visibility(vm, refine=True)
    assert not (vb0 & ~vb).any() and not (vb & ~vm.vl).any() and count(vb).sum() > count(vb0).sum()
    bare = VoxelMap.from_samples(*args, d=0.5, q=2, step=0.125, fine=False)
    assert bare.fine is None
    assert (global_visibility(bare, refine=True) == vb0).all()
