"""The voxel map without the CAD kernel: analytic samples of boxes and spheres."""

from __future__ import annotations

import numpy as np
import pytest

from zmap.access.directions import count, to_bool
from zmap.access.voxelmap import (AccessModelError, Tool, VoxelMap, _ball_inputs, accessibility, global_visibility,
                                  node_directions, paint, parse_holder, parse_tool, set_cover, three_axis)

# one xdist worker compiles this family's numba kernels once (tests/conftest.py)
pytestmark = pytest.mark.xdist_group("access")


def box_samples(lo, hi, step, *, flip=(), fid0=0):
    """Samples of the six faces of an axis box (outward normals; faces in ``flip`` inward)."""
    P, N, F = [], [], []
    fid = fid0
    for ax in range(3):
        for side in (0, 1):
            o = [a for a in range(3) if a != ax]
            u = np.arange(lo[o[0]] + step / 2, hi[o[0]], step)
            v = np.arange(lo[o[1]] + step / 2, hi[o[1]], step)
            U, V = np.meshgrid(u, v, indexing="ij")
            p = np.zeros(U.shape + (3,))
            p[..., o[0]], p[..., o[1]] = U, V
            p[..., ax] = hi[ax] if side else lo[ax]
            n = np.zeros(3)
            n[ax] = 1.0 if side else -1.0
            if fid - fid0 in flip:
                n = -n
            P.append(p.reshape(-1, 3))
            N.append(np.tile(n, (p.size // 3, 1)))
            F.append(np.full(p.size // 3, fid))
            fid += 1
    P, N, F = np.concatenate(P), np.concatenate(N), np.concatenate(F)
    return P, N, np.full(len(P), -0.0), F, np.full(len(P), step * step)


def sphere_samples(centre, r, n, seed=0, fid=0):
    rng = np.random.default_rng(seed)
    p = rng.normal(size=(n, 3))
    p /= np.linalg.norm(p, axis=1)[:, None]
    return (np.asarray(centre) + r * p, p, np.full(n, -1.0 / r), np.full(n, fid),
            np.full(n, 4 * np.pi * r * r / n))


@pytest.fixture(scope="module")
def box():
    vm = VoxelMap.from_samples(*box_samples(np.zeros(3), np.array([12.0, 10.0, 6.0]), 0.2), d=0.8, q=2,
                               step=0.2)
    vg = global_visibility(vm)
    return vm, vg


def test_paint_spreading_of_a_hollow_cube():
    b = np.zeros((6, 6, 6), bool)
    b[1:5, 1:5, 1:5] = True
    b[2:4, 2:4, 2:4] = False
    st = paint(b)
    assert (st == 2).sum() == 8 and (st == 1).sum() == b.sum() and (st == 0).sum() == 216 - 64


def test_box_classification_and_local_maps(box):
    vm, vg = box
    assert vm.n_interior > 0
    # every interior voxel lies strictly inside the box, every exterior one outside it
    c = vm.origin + vm.d * (np.argwhere(vm.state == 2) + 0.5)
    assert ((c > 0) & (c < [12, 10, 6])).all()
    # V'_g is within V'_l, and on a convex box V'_l is each face's open hemisphere
    assert not (vg & ~vm.vl).any()
    ds = vm.directions
    top = vm.voxel_of([[6.0, 5.0, 6.0]])[0]
    assert (to_bool(vm.vl[top], ds.k) == (ds.normals[:, 2] > 0)).all()
    # a convex part hides nothing from a face centre: V'_g = V'_l there
    assert (vg[top] == vm.vl[top]).all()
    assert vm.surface[top] == 5 and not vm.crease[top]
    edge = vm.voxel_of([[6.0, 0.0, 6.0]])[0]
    assert vm.surface[edge] == -1 and vm.crease[edge]


def test_box_access_verdict_and_setups(box):
    vm, vg = box
    A = accessibility(vm, vg, Tool(2.0))
    assert not (A & ~vm.vl).any()  # A' within V'_l
    v = three_axis(vm, A)
    top_area = 12 * 10
    # the top face, less a band of about one ball radius plus a voxel at its edges, is reachable
    assert 0.5 * top_area < v["area_reachable"] <= top_area + 1e-9
    assert v["area_total"] == pytest.approx(2 * (120 + 72 + 60), rel=1e-9)
    setups = set_cover(vm, A)
    covered = sum(s["area"] for s in setups)
    assert covered == pytest.approx(v["area_reachable"] + v["area_other"], rel=1e-9)
    # the first set-up takes most of one of the two largest faces (top or bottom, 120 mm^2 each;
    # tilted towards a side face, which a ball on a plane clears at any tilt, it takes more)
    first = setups[0]["voxels"]
    flat = np.abs(vm.normal[first, 2]) > 0.9
    assert vm.area[first[flat]].sum() >= 0.5 * top_area and setups[0]["area"] >= 0.5 * top_area
    assert all(a["area"] >= b["area"] for a, b in zip(setups, setups[1:]))
    # a tilt cone of 30 degrees about +z reaches the top and, tilted away from them, the side
    # walls down to their foot (the ball's flank on a wall, its shank clear of the wall's
    # plane, nothing under the box), not the bottom
    cone = set_cover(vm, A, cone=np.radians(30))
    got = np.concatenate([c["voxels"] for c in cone])
    assert not (vm.normal[got, 2] < -0.5).any() and (vm.point[got, 2] < 0.8).any()
    assert vm.area[got[vm.point[got, 2] > 5.0]].sum() >= 0.5 * top_area
    assert sum(c["area"] for c in cone) >= v["area_reachable"] - 1e-9
    assert all(np.degrees(np.arccos(c["vector"][2])) <= 30 + 1e-9 for c in cone)
    vox, n = node_directions(vm, A, np.array([6.0, 50.0]), np.array([5.0, 5.0]))
    assert vox[0] == vm.voxel_of([[6.0, 5.0, 6.0]])[0] and vox[1] == -1 and n[1] == 0 and n[0] > 0


@pytest.mark.slow
def test_capsule_map_holds_the_papers_and_answers_edges_by_their_faces(box):
    """The capsule test (the default) keeps every direction of the paper's conditions, and
    more; with the pieces, a top-edge voxel gets the directions both its faces share (the
    paper gives an edge voxel none), and each piece its own face's: the top's +z, the side's
    out and up."""
    vm, vg = box
    ds = vm.directions
    tool = Tool(2.0)
    paper = accessibility(vm, vg, tool, method="paper")
    caps = accessibility(vm, vg, tool)
    assert not (paper & ~caps).any() and count(caps).sum() > count(paper).sum()
    vg2, vp = global_visibility(vm, pieces=True)
    amap, ap = accessibility(vm, vg2, tool, pieces=True)
    assert ap.shape == vp.shape and not (ap & ~vm.pieces.vl).any()
    edge = vm.voxel_of([[6.0, 0.0, 6.0]])[0]  # the top face (z = 6) meets the side y = 0
    assert count(paper[[edge]])[0] == 0
    mine = np.flatnonzero(vm.pieces.voxel == edge)
    top = mine[vm.pieces.normal[mine, 2] > 0.9]
    side = mine[vm.pieces.normal[mine, 1] < -0.9]
    assert len(top) == 1 and len(side) == 1
    assert to_bool(ap[top], ds.k)[0, ds.index("+z")]
    out_up = ds.index((0.0, -1.0, 0.5))
    assert to_bool(ap[side], ds.k)[0, out_up] and not to_bool(ap[top], ds.k)[0, ds.index("-y")]
    assert (amap[edge] == ap[top[0]] & ap[side[0]]).all() and count(amap[[edge]])[0] > 0
    assert not (amap & ~vm.vl).any()
    with pytest.raises(ValueError, match="capsule"):
        accessibility(vm, vg2, tool, method="paper", pieces=True)
    with pytest.raises(ValueError, match="method"):
        accessibility(vm, vg2, tool, method="cone")
    with pytest.raises(AccessModelError, match="samples must be"):
        accessibility(vm, vg2, tool, samples=(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, int)))


def bowl_samples(r=6.0, half=10.0, depth=10.0, step=0.15):
    """A block [-half, half]^2 x [-depth, 0] with a hemispherical cavity of radius r at the origin."""
    P, N, F = [], [], []
    g = np.arange(-half + step / 2, half, step)
    X, Y = np.meshgrid(g, g, indexing="ij")
    top = np.hypot(X, Y) > r
    P.append(np.c_[X[top], Y[top], np.zeros(top.sum())])
    N.append(np.tile([0, 0, 1.0], (top.sum(), 1)))
    F.append(np.zeros(top.sum(), int))
    P.append(np.c_[X.ravel(), Y.ravel(), np.full(X.size, -depth)])
    N.append(np.tile([0, 0, -1.0], (X.size, 1)))
    F.append(np.ones(X.size, int))
    zz = np.arange(-depth + step / 2, 0, step)
    A, Z = np.meshgrid(g, zz, indexing="ij")
    for f, (ax, sgn) in enumerate(((0, 1), (0, -1), (1, 1), (1, -1))):
        p = np.zeros((A.size, 3))
        p[:, ax] = sgn * half
        p[:, 1 - ax] = A.ravel()
        p[:, 2] = Z.ravel()
        n = np.zeros(3)
        n[ax] = sgn
        P.append(p)
        N.append(np.tile(n, (A.size, 1)))
        F.append(np.full(A.size, 2 + f))
    m = int(2 * np.pi * r * r / (step * step))
    rng = np.random.default_rng(5)
    u = rng.normal(size=(m, 3))
    u[:, 2] = -np.abs(u[:, 2])
    u /= np.linalg.norm(u, axis=1)[:, None]
    P.append(r * u)
    N.append(-u)
    F.append(np.full(m, 6))
    P, N, F = np.concatenate(P), np.concatenate(N), np.concatenate(F)
    k = np.where(F == 6, 1.0 / r, 0.0)
    w = np.full(len(P), step * step)
    w[F == 6] = 2 * np.pi * r * r / m
    return P, N, k, F, w


@pytest.fixture(scope="module")
def bowl():
    vm = VoxelMap.from_samples(*bowl_samples(), d=0.5, q=3, step=0.15)
    return vm, global_visibility(vm)


def test_bowl_bottom_sees_a_cone_of_45_degrees(bowl):
    """Thin rays from the bottom of a hemispherical cavity escape within 45 degrees of +z."""
    vm, vg = bowl
    ds = vm.directions
    b = vm.voxel_of([[0.0, 0.0, -6.0]])[0]
    got = to_bool(vg[b], ds.k)
    tilt = np.degrees(np.arccos(np.clip(ds.normals[:, 2], -1, 1)))
    # conservative: nothing beyond the cone (plus the voxel's own spread, 0.5 mm over 6 mm)
    assert not (got & (tilt > 45 + 6)).any()
    # and it keeps the cone's core
    assert got[tilt < 45 - 12].all()


@pytest.mark.slow
def test_bowl_access_shrinks_as_the_ball_grows(bowl):
    vm, vg = bowl
    cav = vm.surface == 6
    maps = [accessibility(vm, vg, Tool(dia)) for dia in (4.0, 6.0, 9.0, 13.0)]
    counts = [int(count(m[cav]).sum()) for m in maps]
    assert counts[0] >= counts[1] >= counts[2] > counts[3] == 0  # a 13 mm ball does not fit in r = 6
    # not pair by pair: the ball's centre moves with a, so E_n(v) and the shank's start are
    # not nested, and the voxel margins weigh more on a small ball (see the hand-over note)
    # the curvature condition: the 13 mm ball is refused for the curvature 1/6 > 1/6.5
    assert (vm.curvature[cav] == pytest.approx(1 / 6.0))


@pytest.mark.slow
def test_bowl_access_on_samples_shrinks_pair_by_pair_and_finds_the_cone(bowl):
    """On the samples the capsule of a larger ball holds the smaller one's (its centre moves
    along the normal by the difference of the radii), so A' shrinks pair by pair as the ball
    grows; at the bottom of the cavity (r = 6) a ball of radius a leaves along the directions
    whose axis from its centre (r - a below the rim's plane) passes the rim circle at more
    than a (which also keeps it off the cavity's wall below)."""
    vm, vg = bowl
    P, N, _, F, _ = bowl_samples()
    maps = [accessibility(vm, vg, Tool(dia), samples=(P, N, F)) for dia in (2.0, 4.0, 6.0, 9.0, 13.0)]
    for small, big in zip(maps, maps[1:]):
        assert not (big & ~small).any()
    cav = vm.surface == 6
    assert count(maps[-1][cav]).sum() == 0 and count(maps[2][cav]).sum() > 0
    ds = vm.directions
    b = vm.voxel_of([[0.0, 0.0, -6.0]])[0]
    r = 6.0
    for m, a in zip(maps[:3], (1.0, 2.0, 3.0)):
        got = to_bool(m[b], ds.k)
        # the axis from c = (0, 0, a - r) along n, against the rim circle of radius r at z = 0:
        # its distance to the nearest rim point, with the ball's centre allowed a sample step
        n = ds.normals
        up = n[:, 2] > 1e-9
        s_ = np.where(up, (r - a) / np.where(up, n[:, 2], 1.0), 0.0)
        hit = np.hypot(s_ * n[:, 0], s_ * n[:, 1])  # where the axis crosses z = 0
        clear = np.where(up, (r - hit) * n[:, 2], -1.0)  # distance to the rim, to first order
        assert not (got & (clear < a - 0.3)).any()
        assert got[clear > a + 0.3].all()


def _ball_conditions_brute(vm, vg, a, voxels):
    """Conditions 1-3 of the ball-end map for ``voxels`` by plain numpy: the shell from all
    boundary centres, the fit test from all boundary and interior centres (no grid search)."""
    ds = vm.directions
    hd, bad, cap = _ball_inputs(vm, a)
    bad_self, bad = (bad & 1).astype(bool), (bad & 2).astype(bool)
    r_in, r_out = a - hd, a + hd
    centre = vm.point + a * vm.normal
    solid = vm.origin + vm.d * (np.argwhere(vm.state != 0) + 0.5)
    out = np.where(bad_self[voxels, None], np.uint64(0), vg[voxels])
    for row, b in enumerate(voxels):
        if bad_self[b] or (np.linalg.norm(solid - centre[b], axis=1) < r_in).any():
            out[row] = 0
            continue
        off = vm.centres - centre[b]
        shell = np.flatnonzero(np.linalg.norm(off, axis=1) <= r_out)
        t = ds.lookup(off[shell])
        keep = np.where(bad[shell, None], cap[t], vg[shell] | cap[t])
        out[row] &= np.bitwise_and.reduce(keep, axis=0)
    return out


@pytest.mark.slow
def test_ball_conditions_match_a_plain_search(bowl):
    """The shell scan (columns cut to the sphere, in parallel, no neighbour lists) gives the
    bits of a plain search over every voxel centre."""
    from zmap.access._access_kernels import ball_conditions

    vm, vg = bowl
    ds = vm.directions
    a = 2.0
    hd, bad, cap = _ball_inputs(vm, a)
    centre = np.ascontiguousarray(vm.point + a * vm.normal)
    got = np.empty_like(vg)
    ball_conditions(np.ascontiguousarray(vg), np.ascontiguousarray(vm.centres), centre, vm.origin, vm.d, vm.index,
                    vm.state, a - hd, a + hd, bad, cap, ds._centres, ds._frames, ds.q, got)
    # every voxel of the cavity and a random third of the others
    cav = np.flatnonzero(vm.surface == 6)
    rest = np.random.default_rng(0).permutation(np.flatnonzero(vm.surface != 6))
    voxels = np.concatenate([cav, rest[:len(rest) // 3]])
    want = _ball_conditions_brute(vm, vg, a, voxels)
    assert np.array_equal(got[voxels], want)
    # the conditions bite, and not only by the fit test
    assert count(want).sum() > 0 and ((count(want) < count(vg[voxels])) & (count(want) > 0)).any()


def test_open_surface_and_pieces_are_reported():
    p, n, k, f, w = box_samples(np.zeros(3), np.array([6.0, 6.0, 6.0]), 0.2)
    keep = f != 5  # no top face: the paint leaks in
    with pytest.raises(AccessModelError, match="no interior voxels"):
        VoxelMap.from_samples(p[keep], n[keep], k[keep], f[keep], w[keep], d=1.0, q=1, step=0.2)
    a = box_samples(np.zeros(3), np.array([4.0, 4.0, 4.0]), 0.2)
    b = box_samples(np.array([10.0, 0, 0]), np.array([14.0, 4.0, 4.0]), 0.2, fid0=6)
    both = [np.concatenate([x, y]) for x, y in zip(a, b)]
    with pytest.raises(AccessModelError, match=r"2 pieces .* faces 6-11 near \(12.0, 2.0, 2.0\)"):
        VoxelMap.from_samples(*both, d=1.0, q=1, step=0.2)


def test_inward_faces_are_turned_and_mixed_ones_uncertain():
    vm = VoxelMap.from_samples(*box_samples(np.zeros(3), np.array([6.0, 6.0, 6.0]), 0.2, flip=(5,)),
                               d=1.0, q=2, step=0.2)
    assert vm.flipped == [5]
    top = vm.voxel_of([[3.0, 3.0, 6.0]])[0]
    assert vm.normal[top] @ [0, 0, 1] > 0.99
    p, n, k, f, w = box_samples(np.zeros(3), np.array([6.0, 6.0, 6.0]), 0.2)
    half = (f == 5) & (p[:, 0] < 3)
    n[half] *= -1
    # a face pointing both ways: the samples that disagree are turned, their voxels uncertain
    vm = VoxelMap.from_samples(p, n, k, f, w, d=1.0, q=2, step=0.2)
    top = vm.voxel_of(p[half])
    assert vm.uncertain[top].all() and vm.uncertain.sum() == len(np.unique(top))
    inner = vm.voxel_of(p[half & (p[:, 0] > 1.2) & (np.abs(p[:, 1] - 3) < 1.8)])
    assert (vm.normal[inner] @ [0, 0, 1] > 0.99).all()  # turned (away from the edges: interior in front)
    assert vm.uncertain_info["regions"][0]["faces"] == [5]
    # refused only when they are a large share of the boundary
    with pytest.raises(AccessModelError, match=r"8.3 % of the boundary area .* more than the 5 % allowed"):
        VoxelMap.from_samples(p, n, k, f, w, d=1.0, q=2, step=0.2, max_uncertain=0.05)


@pytest.mark.parametrize("kw,match", [(dict(d=0.0), "voxel size d must be a positive"),
                                      (dict(d=-1.0), "voxel size d must be a positive"),
                                      (dict(d=1.0, step=1.0), "d' must be positive and smaller"),
                                      (dict(d=1.0, q=0), "q must be an integer >= 1")])
def test_bad_arguments(kw, match):
    args = dict(d=1.0, q=1, step=0.2)
    args.update(kw)
    with pytest.raises(AccessModelError, match=match):
        VoxelMap.from_samples(*box_samples(np.zeros(3), np.array([3.0, 3.0, 3.0]), 0.2), **args)


def test_tool_larger_than_the_part(box):
    vm, vg = box
    with pytest.raises(AccessModelError, match="tool diameter 40 mm is larger than the part"):
        accessibility(vm, vg, Tool(40.0))


@pytest.mark.parametrize("spec,value", [("ball:6", 6.0), ("ball:0.5", 0.5)])
def test_parse_tool(spec, value):
    assert parse_tool(spec) == value


@pytest.mark.parametrize("spec", ["flat:6", "ball:-2", "ball:", "ball:x", "6"])
def test_parse_tool_refuses(spec):
    with pytest.raises(AccessModelError, match="is not 'ball:DIAMETER'"):
        parse_tool(spec)


def test_parse_holder():
    assert parse_holder("20x40") == (20.0, 40.0)
    with pytest.raises(AccessModelError, match="DIAMETERxLENGTH"):
        parse_holder("20")
    with pytest.raises(AccessModelError, match="holder diameter 4 mm is smaller"):
        Tool(6.0, holder_diameter=4.0, holder_length=10.0)


@pytest.mark.slow
def test_cylinder_casting_kernel_matches_the_plain_reference():
    """The depth-buffer kernel gives the same V'_g bits as the pair-by-pair reference."""
    from tests.reference.access import global_visibility_reference

    # an L-shaped part (a box with a step): concave edges make the casting delete directions
    a = box_samples(np.zeros(3), np.array([4.0, 3.0, 2.0]), 0.25)
    b = box_samples(np.array([0.0, 0.0, 2.0]), np.array([2.0, 3.0, 3.2]), 0.25, fid0=6)
    keep = ~((a[3] == 5) & (a[0][:, 0] < 2.0))  # the lower top face under the upper box
    vm = VoxelMap.from_samples(*[np.concatenate([x[keep], y]) for x, y in zip(a, b)], d=0.6, q=1,
                               step=0.25, check=False)
    fast = global_visibility(vm)
    slow = global_visibility_reference(vm)
    assert (fast == slow).all()
    assert (count(fast) < count(vm.vl)).any()  # the step's concave edge hides directions


def test_only_concave_creases_bar_the_ball():
    """An L-shaped block (a step on a block, off the voxel grid's planes): the step's foot
    (x = 2.17, z = 2.13) is a concave edge, every other edge and corner convex or a flat join.
    The ball's crease condition keeps the crease voxels along the foot and drops the others."""
    from zmap.access.voxelmap import _concave_creases

    a = box_samples(np.zeros(3), np.array([4.13, 3.07, 2.13]), 0.1)
    b = box_samples(np.array([0.0, 0.0, 2.13]), np.array([2.17, 3.07, 3.3]), 0.1, fid0=6)
    keep_a = ~((a[3] == 5) & (a[0][:, 0] < 2.17))
    keep_b = b[3] != 10  # the step's bottom lies on the block
    vm = VoxelMap.from_samples(*[np.concatenate([x[keep_a], y[keep_b]]) for x, y in zip(a, b)], d=0.4, q=2,
                               step=0.1, check=False)
    concave = _concave_creases(vm)
    assert not (concave & ~vm.crease).any()
    foot = np.hypot(vm.centres[:, 0] - 2.17, vm.centres[:, 2] - 2.13)
    near = vm.crease & (foot < 0.3)
    assert concave[near].all() and near.sum() >= 7
    assert not concave[foot > 0.8].any() and vm.crease[foot > 0.8].sum() > 50
