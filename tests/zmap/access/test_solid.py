"""The material rules (closed shell, below an open surface) and the uncertain voxels of thin
walls, on analytic samples."""

from __future__ import annotations

import numpy as np
import pytest

from tests.zmap.access.test_voxelmap import box_samples
from zmap.access.directions import count, to_bool
from zmap.access.solid import describe, nice_voxel, open_walls
from zmap.access.voxelmap import (EXTERIOR, INTERIOR, AccessModelError, AccessResult, Tool, VoxelMap,
                                  accessibility, global_visibility, three_axis)

# one xdist worker compiles this family's numba kernels once (tests/conftest.py)
pytestmark = pytest.mark.xdist_group("access")


def dome_samples(step=0.1, half=6.0, h=2.0, flip=False):
    """An open surface z = h cos^2(pi r / (2 * 4)) for r < 4 (0 beyond) over [-half, half]^2:
    one face, no solid, as a die face is delivered."""
    g = np.arange(-half + step / 2, half, step)
    X, Y = np.meshgrid(g, g, indexing="ij")
    R = np.hypot(X, Y)
    c = np.pi / 8
    Z = np.where(R < 4, h * np.cos(c * R) ** 2, 0.0)
    dzdr = np.where(R < 4, -2 * h * c * np.cos(c * R) * np.sin(c * R), 0.0)
    Rs = np.maximum(R, 1e-12)
    gx, gy = dzdr * X / Rs, dzdr * Y / Rs
    n = np.stack([-gx, -gy, np.ones_like(gx)], axis=-1)
    n /= np.linalg.norm(n, axis=-1)[..., None]
    if flip:
        n = -n
    P = np.stack([X, Y, Z], axis=-1).reshape(-1, 3)
    N = n.reshape(-1, 3)
    w = step * step / np.abs(N[:, 2])
    return P, N, np.zeros(len(P)), np.zeros(len(P), int), w


def test_open_surface_takes_the_material_below_it():
    P, N, K, F, W = dome_samples()
    with pytest.raises(AccessModelError, match="no interior voxels.*--solid below"):
        VoxelMap.from_samples(P, N, K, F, W, d=0.5, q=1, step=0.1)
    vm = VoxelMap.from_samples(P, N, K, F, W, d=0.5, q=1, step=0.1, solid="below", floor=-2.0)
    assert vm.solid == "below" and "below the top surface" in vm.solid_note and vm.floor == -2.0
    assert not vm.uncertain.any()
    # per column: interior from the floor up to the surface at the column's centre, exterior above
    for x, y in [(0.1, 0.1), (2.3, -1.2), (-5.2, 4.9)]:
        i, j = np.floor((np.array([x, y]) - vm.origin[:2]) / vm.d).astype(int)
        xc, yc = vm.origin[:2] + vm.d * (np.array([i, j]) + 0.5)
        r = np.hypot(xc, yc)
        top = 2.0 * np.cos(np.pi / 8 * r) ** 2 if r < 4 else 0.0
        zc = vm.origin[2] + vm.d * (np.arange(vm.state.shape[2]) + 0.5)
        col = vm.state[i, j]
        assert (col[(zc > -2.0 + 1e-9) & (zc < top - vm.d)] == INTERIOR).all()
        assert (col[zc > top + vm.d] == EXTERIOR).all() and (col[zc < -2.0] == EXTERIOR).all()
    # auto turns to the rule below where the paint leaks, and says so; a floor above the part fails
    auto = VoxelMap.from_samples(P, N, K, F, W, d=0.5, q=1, step=0.1, solid="auto")
    assert auto.solid == "below" and "paint leaked" in auto.solid_note and auto.floor == pytest.approx(-1.0)
    with pytest.raises(AccessModelError, match="above the part's lowest point"):
        VoxelMap.from_samples(P, N, K, F, W, d=0.5, q=1, step=0.1, solid="below", floor=0.5)
    with pytest.raises(AccessModelError, match="not to a closed shell"):
        VoxelMap.from_samples(P, N, K, F, W, d=0.5, q=1, step=0.1, floor=-1.0)
    with pytest.raises(AccessModelError, match="'above' is not one of"):
        VoxelMap.from_samples(P, N, K, F, W, d=0.5, q=1, step=0.1, solid="above")
    # a face delivered pointing down is turned to face the tool
    down = VoxelMap.from_samples(*dome_samples(flip=True), d=0.5, q=1, step=0.1, solid="below")
    assert down.flipped == [0] and (down.normal[:, 2] > 0).all()


def test_open_die_face_verdict_and_walls():
    P, N, K, F, W = dome_samples()
    vm = VoxelMap.from_samples(P, N, K, F, W, d=0.5, q=2, step=0.1, solid="below", floor=-2.0)
    walls = open_walls(vm)
    # the material's four sides and its floor (2 x 2 points per voxel face), within a voxel of them
    assert len(walls) and np.isclose(walls[:, 2].min(), -2.0) and (np.abs(walls[:, :2]).max() <= 6.0 + vm.d)
    side = np.abs(walls[:, :2]).max(axis=1) > 6.0 - vm.d
    assert (side | np.isclose(walls[:, 2], -2.0)).all()
    vg, vgp = global_visibility(vm, pieces=True)
    A = accessibility(vm, vg, Tool(2.0), samples=(P, N, F))
    v = three_axis(vm, A)
    assert v["share"] > 0.99 and v["uncertain_share"] == 0.0  # a smooth dome: all of it from +z
    # a ball on the surface within its radius of the material's side cannot go sideways and down
    edge = vm.voxel_of([[5.9, 0.05, 0.0]])[0]
    down = (vm.directions.normals[:, 2] < -0.2) & (vm.directions.normals[:, 0] > 0.5)
    assert down.any() and not to_bool(A[edge], vm.directions.k)[down].any()
    closed = VoxelMap.from_samples(*box_samples(np.zeros(3), np.array([6.0, 6.0, 6.0]), 0.2), d=1.0, q=1, step=0.2)
    assert len(open_walls(closed)) == 0


def rib_samples(t=0.3, d_step=0.1):
    """A block 10 x 10 x 4 with a rib t thick (x from 5 - t/2), 8 long and 4 tall on its top."""
    P, N, K, F, W = box_samples(np.zeros(3), np.array([10.0, 10.0, 4.0]), 0.2)
    r = box_samples(np.array([5 - t / 2, 1.0, 4.0]), np.array([5 + t / 2, 9.0, 8.0]), d_step, fid0=6)
    keep = r[3] != 6 + 4  # the rib's bottom sits on the block
    return tuple(np.concatenate([a, b[keep]]) for a, b in zip((P, N, K, F, W), r))


@pytest.fixture(scope="module")
def rib():
    P, N, K, F, W = rib_samples()
    vm = VoxelMap.from_samples(P, N, K, F, W, d=0.5, q=2, step=0.1)
    vg, vgp = global_visibility(vm, pieces=True)
    return (P, N, K, F, W), vm, vg, vgp


def test_thin_rib_is_uncertain_reported_and_not_failed(rib):
    (P, N, K, F, W), vm, vg, vgp = rib
    side = (F == 6) | (F == 7)  # the rib's two long sides, 0.3 mm apart
    # all but the voxels of the block's top layer, where its top face's samples fill every
    # voxel and no voxel off the boundary lies within reach
    assert vm.uncertain[vm.voxel_of(P[side & (P[:, 2] > 4.5)])].all()
    # only the rib's voxels: none of the block's away from it
    far = vm.voxel_of(P[(F < 6) & (np.abs(P[:, 0] - 5) > 1.5)])
    assert not vm.uncertain[far].any()
    u = vm.uncertain_info
    assert u["voxels"] == int(vm.uncertain.sum()) and u["share"] == pytest.approx(u["area"] / vm.area.sum())
    assert len(u["regions"]) == 1 and u["regions"][0]["faces"] == [6, 7]
    assert np.allclose(u["regions"][0]["centre"][:2], [5.0, 5.0], atol=0.1)
    assert u["thickness"] == pytest.approx(0.3, abs=0.02) and u["suggest_d"] == 0.1 == nice_voxel(0.3)
    text = "\n".join(describe(vm))
    assert "closed shell" in text and "--voxel 0.1 would resolve them" in text and "faces 6-7" in text
    # refused only when they are a large share of the boundary
    with pytest.raises(AccessModelError, match=r"13.3 % of the boundary area .* 5 % allowed.*--voxel 0.1"):
        VoxelMap.from_samples(P, N, K, F, W, d=0.5, q=2, step=0.1, max_uncertain=0.05)


def test_uncertain_voxels_block_every_direction_through_them(rib):
    (P, N, K, F, W), vm, vg, vgp = rib
    ds = vm.directions
    # the block's top beside the rib: no direction that crosses the rib's cube stays, whichever
    # side of the rib it comes from (the casting does not trust the rib's faces' light sets)
    for x, sgn in ((4.1, 1.0), (5.9, -1.0)):
        b = vm.voxel_of([[x, 5.0, 4.0]])[0]
        n = ds.normals
        rise = n[:, 2] / np.maximum(sgn * n[:, 0], 1e-12)  # height gained per mm toward the rib
        toward = (sgn * n[:, 0] > 0.3) & (np.abs(n[:, 1]) < 0.2 * sgn * n[:, 0]) & (rise * 1.5 < 3.5)
        assert toward.any() and not to_bool(vg[b], ds.k)[toward].any()
    # an uncertain voxel's tool map holds no direction its own cast lost
    A, Ap = accessibility(vm, vg, Tool(2.0), pieces=True, samples=(P, N, F), vg_pieces=vgp)
    unc = vm.uncertain
    assert not (A[unc] & ~vg[unc] & ~_pieces_or(vm, vgp)[unc]).any()
    pu = unc[vm.pieces.voxel]
    assert not (Ap[pu] & ~vgp[pu]).any()
    # the rib's top is still reached from +z (the part does not fail, nor the rib vanish)
    top = vm.voxel_of(P[F == 11])
    assert (count(A[top]) > 0).mean() > 0.5
    v = three_axis(vm, A)
    assert v["uncertain_share"] == pytest.approx(vm.uncertain_info["share"])
    res = AccessResult(vm=vm, vg=vg, amap=A, tool=Tool(2.0), verdict=v, setups=[], seconds={})
    assert "uncertain (walls or gaps thinner than the voxel)" in res.summary()


def _pieces_or(vm, vgp):
    """Per voxel, the OR of its pieces' V'_g (a crease voxel takes its pieces' directions)."""
    out = np.zeros((vm.n_boundary, vgp.shape[1]), dtype=np.uint64)
    np.bitwise_or.at(out, vm.pieces.voxel, vgp)
    return out
