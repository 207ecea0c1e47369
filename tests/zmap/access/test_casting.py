"""The casting's blockers and starts: the patch slab, the tight boxes, one piece per face where
faces meet, against the samples they bound and the pair-by-pair reference."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.reference.access import global_visibility_reference
from zmap.access.directions import count, to_bool
from zmap.access.voxelmap import VoxelMap, global_visibility

from .test_voxelmap import bowl_samples, box_samples

# one xdist worker compiles this family's numba kernels once (tests/conftest.py)
pytestmark = pytest.mark.xdist_group("access")

corner = st.tuples(*[st.floats(-0.7, 0.7, allow_nan=False)] * 3)
size = st.tuples(*[st.floats(2.0, 4.0, allow_nan=False)] * 3)


def _box_map(lo, dims, d=0.5, q=1, step=0.125):
    lo = np.asarray(lo, dtype=float)
    return VoxelMap.from_samples(*box_samples(lo, lo + np.asarray(dims), step), d=d, q=q, step=step)


@settings(max_examples=15, deadline=None)
@given(lo=corner, dims=size, tilt=st.floats(0.0, 0.6))
def test_slabs_and_boxes_hold_every_sample(lo, dims, tilt):
    """Every sample lies in its voxel's tight box and its piece's box, on the inner side of
    neither slab; flat faces square to an axis give boxes flat across that axis."""
    P, N, K, F, W = box_samples(np.asarray(lo), np.asarray(lo) + np.asarray(dims), 0.125)
    c, s = np.cos(tilt), np.sin(tilt)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])  # turn about z: x, y faces tilt
    vm = VoxelMap.from_samples(P @ R.T, N @ R.T, K, F, W, d=0.5, q=1, step=0.125)
    P, N = P @ R.T, N @ R.T
    v = vm.voxel_of(P)
    tol = 1e-9
    assert (P >= vm.tight_lo[v] - tol).all() and (P <= vm.tight_hi[v] + tol).all()
    assert (((P - vm.point[v]) * vm.normal[v]).sum(axis=1) >= -vm.slab[v] - tol).all()
    one = vm.surface[v] >= 0
    # the top and bottom faces (normal +-z) stay flat across z whatever the turn
    flat = one & (np.abs(N[:, 2]) == 1.0)
    assert (vm.tight_hi[v[flat], 2] - vm.tight_lo[v[flat], 2] <= 2e-6 * 0.125 + 1e-12).all()
    p = vm.pieces
    # pieces exactly where faces meet in a voxel (a box whose faces all fall on voxel
    # boundaries, as hypothesis found, has none)
    assert (len(p.voxel) > 0) == bool((~one).any()) and (vm.surface[p.voxel] < 0).all()
    # each sample of a voxel where faces meet lies in the piece of its face
    multi = np.flatnonzero(~one)
    for idx in multi[:: max(1, len(multi) // 200)]:
        js = np.flatnonzero(p.voxel == v[idx])
        inside = [((P[idx] >= p.lo[j] - tol) & (P[idx] <= p.hi[j] + tol)).all()
                  and ((P[idx] - p.point[j]) @ p.normal[j] >= -p.slab[j] - tol) for j in js]
        assert any(inside)
    # a voxel's L' holds the OR of its pieces' (more blocks more: the casting stays
    # conservative); equal on a box square to the axes (on a turned one, see below)
    for b in np.unique(p.voxel)[:50]:
        union = np.bitwise_or.reduce(p.light[p.voxel == b], axis=0)
        assert ((union & ~vm.light[b]) == 0).all()
        if tilt == 0.0:
            assert (union == vm.light[b]).all()


@pytest.mark.xfail(reason="known defect: on a box turned about z at q = 1, voxels where two faces meet keep "
                          "every direction in L' while their pieces' L' leave some out (conservative: it "
                          "blocks more, never less)", strict=True)
def test_turned_box_voxel_light_is_the_or_of_its_pieces():
    lo, dims, tilt = np.zeros(3), np.array((2.0, 2.578125, 2.0)), 0.4375  # found by hypothesis
    P, N, K, F, W = box_samples(lo, lo + dims, 0.125)
    c, s = np.cos(tilt), np.sin(tilt)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    vm = VoxelMap.from_samples(P @ R.T, N @ R.T, K, F, W, d=0.5, q=1, step=0.125)
    p = vm.pieces
    for b in np.unique(p.voxel):
        assert (np.bitwise_or.reduce(p.light[p.voxel == b], axis=0) == vm.light[b]).all()


def test_slab_start_only_lifts_blocks():
    """Starting the lines at the patch's slab drops blocks, never adds one; on a box whose
    faces lie on voxel planes (the interior cubes right under them) it drops many."""
    vm = _box_map([0.0, 0.0, 0.0], [4.0, 4.0, 3.0], q=2)
    with_slab = global_visibility(vm)
    without = global_visibility(dataclasses.replace(vm, slab=None))
    assert not (without & ~with_slab).any()
    assert count(with_slab).sum() > count(without).sum()
    # a convex box hides nothing within 45 deg of the normal from a face's voxels a voxel or
    # more from its edges (nearer, a blocker's growth by a ray's offset from its line shows)
    ds = vm.directions
    lo, hi = np.zeros(3), np.array([4.0, 4.0, 3.0])
    p = vm.point
    axis = np.abs(vm.normal).argmax(axis=1)
    edge = np.min([np.where(axis == a, np.inf, np.minimum(p[:, a] - lo[a], hi[a] - p[:, a])) for a in range(3)], axis=0)
    inner = np.flatnonzero((vm.surface >= 0) & (edge > vm.d))
    assert len(inner) > 50
    near = (vm.normal[inner] @ ds.normals.T) > np.cos(np.radians(45))
    assert to_bool(with_slab[inner], ds.k)[near].all()


def test_pieces_only_lift_blocks_on_a_convex_box():
    """Edge voxels as one piece per face block no more than the box around both faces."""
    vm = _box_map([0.1, 0.2, 0.3], [3.0, 2.5, 2.0], q=2)
    a = global_visibility(vm)
    b = global_visibility(dataclasses.replace(vm, pieces=None))
    assert not (b & ~a).any()
    assert count(a).sum() > count(b).sum()


@pytest.mark.slow
def test_casting_kernel_matches_the_reference_on_a_bowl():
    """Curved faces, edges where the cavity meets the top, slabs that are not flat: the kernel
    gives the reference's bits."""
    vm = VoxelMap.from_samples(*bowl_samples(r=2.0, half=3.0, depth=2.5, step=0.15), d=0.6, q=1, step=0.15)
    assert vm.pieces is not None and len(vm.pieces.voxel) > 0 and (vm.slab[vm.surface == 6] > 0).mean() > 0.5
    fast = global_visibility(vm)
    assert (fast == global_visibility_reference(vm)).all()
    assert (count(fast) < count(vm.vl)).any()


@settings(max_examples=40, deadline=None)
@given(shape=st.tuples(*[st.integers(1, 6)] * 3), codes=st.integers(1, 3), seed=st.integers(0, 2**31 - 1),
       fill=st.floats(0.0, 1.0))
@pytest.mark.slow
def test_merged_runs_cover_every_coded_voxel_once_with_its_code(shape, codes, seed, fill):
    from zmap.access._access_kernels import merge_runs

    rng = np.random.default_rng(seed)
    code = np.where(rng.random(shape) < fill, rng.integers(1, codes + 1, shape), 0).astype(np.int64)
    rows = np.empty((code.size, 7), dtype=np.int64)
    n = merge_runs(code, rows)
    seen = np.zeros(shape, dtype=np.int64)
    for i0, j0, l0, i1, j1, l1, c in rows[:n]:
        block = code[i0:i1 + 1, j0:j1 + 1, l0:l1 + 1]
        assert block.size and (block == c).all()
        seen[i0:i1 + 1, j0:j1 + 1, l0:l1 + 1] += 1
    assert ((seen == 1) == (code > 0)).all() and seen.max(initial=0) <= 1


@pytest.mark.slow
def test_merged_skin_boxes_give_the_bits_of_the_cubes(monkeypatch):
    """The casting draws the skin as boxes of cubes with one neighbour mask, with the chord
    cut on long boxes; the bits are those of the single cubes (and of the reference)."""
    import zmap.access.casting as V

    vm = _box_map((0.1, -0.2, 0.05), (6.0, 3.5, 4.0), d=0.5, q=2)
    sijk = vm.skin_ijk()
    merged = global_visibility(vm)
    assert len(V._skin_boxes(vm, sijk, np.zeros(len(sijk), dtype=np.int64))[0]) < len(sijk) / 4

    def cubes(vm, sijk, smask):
        c = np.ascontiguousarray(vm.origin + vm.d * (sijk + 0.5))
        return c, np.full_like(c, 0.5 * vm.d), smask

    monkeypatch.setattr(V, "_skin_boxes", cubes)
    assert (global_visibility(vm) == merged).all()
    assert (global_visibility_reference(vm) == merged).all()


@pytest.mark.slow
def test_merged_flat_blockers_give_the_bits_of_the_voxels(monkeypatch):
    """The flat boxes of a box's faces merge into a few blockers per face, with the bits of
    one blocker per voxel (and of the reference); voxels that query and block one direction
    (the paper's tessel sets) stay apart."""
    import zmap.access.casting as V

    for exact in (True, False):
        lo = np.array((0.1, -0.2, 0.05))
        vm = VoxelMap.from_samples(*box_samples(lo, lo + np.array((6.0, 3.5, 4.0)), 0.125), d=0.5, q=2,
                                   step=0.125, exact=exact)
        blk = vm.blockers()
        few = V._merged_blockers(vm, blk)
        assert len(few[0]) < 0.75 * len(blk[0])
        merged = global_visibility(vm)
        monkeypatch.setattr(V, "_merged_blockers", lambda vm, b: b)
        assert (global_visibility(vm) == merged).all()
        assert (global_visibility_reference(vm) == merged).all()
        monkeypatch.undo()
        if not exact:
            assert V._self_blocking(vm).any()


def test_piece_queries_match_the_reference_on_a_bowl():
    """Each face's piece in an edge voxel is cast as a query of its own: its bits are the
    reference's, the voxels' bits do not change, and a piece keeps directions that its
    voxel (the AND over its faces) loses."""
    vm = VoxelMap.from_samples(*bowl_samples(r=2.0, half=3.0, depth=2.5, step=0.15), d=0.6, q=1, step=0.15)
    p = vm.pieces
    assert len(p.voxel) > 0 and p.vl.shape == (len(p.voxel), vm.directions.words)
    vg, vp = global_visibility(vm, pieces=True)
    assert (vg == global_visibility(vm)).all()
    assert (vp == global_visibility_reference(vm, pieces=True)).all()
    assert (count(vp) > count(vg[p.voxel])).sum() > len(p.voxel) // 4
    # a piece's V'_l holds its voxel's (the voxel's is the AND over its pieces')
    assert not (vm.vl[p.voxel] & ~p.vl).any()


@settings(max_examples=30, deadline=None)
@given(k=st.integers(1, 200), m=st.integers(0, 300), seed=st.integers(0, 2**31 - 1))
def test_packed_columns_are_the_bitsets_of_the_transpose(k, m, seed):
    from zmap.access._access_kernels import pack_columns
    from zmap.access.directions import from_bool, words_for

    out = (np.random.default_rng(seed).random((k, m)) < 0.4).astype(np.uint8)
    bits = np.empty((m, words_for(k)), dtype=np.uint64)
    pack_columns(out, bits)
    assert (bits == from_bool(out.T.astype(bool))).all()


@settings(max_examples=30, deadline=None)
@given(n=st.integers(1, 400), cols=st.integers(1, 6), span=st.integers(1, 4), seed=st.integers(0, 2**31 - 1))
def test_row_groups_are_the_groups_of_equal_rows(n, cols, span, seed):
    import zmap.access.casting as V

    key = np.random.default_rng(seed).integers(-span, span, (n, cols)).astype(np.int64)
    g = V._row_groups(key)
    same = (key[:, None, :] == key[None, :, :]).all(axis=2)
    assert ((g[:, None] == g[None, :]) == same).all()
