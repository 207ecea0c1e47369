"""cad_io.access on cadquery parts with closed-form answers, the OCC reference, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import DATA, STEP_DATA
from zmap.access.directions import to_bool
from zmap.access.voxelmap import AccessModelError, Tool, accessibility, global_visibility, three_axis

# one xdist worker compiles this family's numba kernels once (tests/conftest.py)
pytestmark = pytest.mark.xdist_group("access")

cq = pytest.importorskip("cadquery")

W, D, LX, LY, H = 8.0, 6.0, 30.0, 20.0, 12.0  # slot width, depth; block x, y, height


def _write(shape, path):
    cq.exporters.export(shape, str(path))
    from cad_io.step import read_step

    return read_step(path)


@pytest.fixture(scope="module")
def slot(tmp_path_factory):
    """A block LX x LY x H (top at z = 0) with a slot W wide and D deep along y, open at both ends."""
    blk = (cq.Workplane("XY").box(LX, LY, H).translate((0, 0, -H / 2))
           .cut(cq.Workplane("XY").box(W, LY + 10, D).translate((0, 0, -D / 2))))
    part = _write(blk, tmp_path_factory.mktemp("slot") / "slot.step")
    from cad_io.access import voxelize

    vm = voxelize(part, 0.5, q=3)
    return part, vm, global_visibility(vm)


def slot_visible(p, n):
    """Closed form: does the thin ray from floor point p along n leave the slot?"""
    n = np.atleast_2d(n)
    nz = n[:, 2]
    up = nz > 1e-9
    t_top = np.where(up, (0.0 - p[2]) / np.where(up, nz, 1), np.inf)
    ny = np.where(np.abs(n[:, 1]) > 1e-12, n[:, 1], 1e-12)
    t_end = (np.sign(ny) * LY / 2 - p[1]) / ny  # leaves through a slot end
    t = np.minimum(t_top, t_end)
    x = p[0] + n[:, 0] * t
    return up & (np.abs(x) < W / 2)


def slot_tool_clearance(c, n):
    """Closed form for the tool axis c + s n (s >= 0) through the slot's top: its distance to the two
    top edges of the walls (lines x = +-W/2, z = 0 along y) and to the floor."""
    n = np.atleast_2d(n)
    out = np.full(len(n), np.inf)
    for sx in (1.0, -1.0):
        e = np.array([sx * W / 2, 0.0, 0.0])
        cr = np.stack([-n[:, 2], np.zeros(len(n)), n[:, 0]], axis=1)  # n x y
        lc = np.linalg.norm(cr, axis=1)
        dist = np.abs(cr @ (e - c)) / np.maximum(lc, 1e-12)
        out = np.minimum(out, dist)
    return out


@pytest.mark.slow
def test_slot_thin_rays_closed_form(slot):
    part, vm, vg = slot
    ds = vm.directions
    for x0 in (0.0, 2.0):
        p = np.array([x0, 0.0, -D])
        b = vm.voxel_of([p + [0, 0, 1e-9]])[0]
        assert b >= 0
        got = to_bool(vg[b], ds.k)
        lo, hi = vm.box_lo[b], vm.box_hi[b]
        # conservative: every direction kept is free from both ends of the voxel's floor box
        for cx in (lo[0], hi[0]):
            for cy in (lo[1], hi[1]):
                assert not (got & ~slot_visible(np.array([cx, cy, -D]), ds.normals)).any()
        # and nothing is lost that stays free with two voxels of slack on either side
        slack = slot_visible(p + [1.0, 0, 0], ds.normals) & slot_visible(p - [1.0, 0, 0], ds.normals)
        slack &= ds.normals[:, 2] > np.sin(np.radians(10))
        assert got[slack].all()


@pytest.mark.slow
def test_slot_ball_closed_form_and_occ(slot):
    part, vm, vg = slot
    ds = vm.directions
    a = 2.0
    A = accessibility(vm, vg, Tool(2 * a))
    p = np.array([0.0, 0.0, -D])
    b = vm.voxel_of([p + [0, 0, 1e-9]])[0]
    got = to_bool(A[b], ds.k)
    c = vm.point[b] + a * vm.normal[b]
    across = np.abs(ds.normals[:, 1]) < 0.15  # axis leaves through the top, not a slot end
    clear = slot_tool_clearance(c, ds.normals)
    # the ball clears the walls (W/2 > a) and the shank the wall edges, closed form
    assert not (got & across & (clear < a)).any()
    assert got[across & (clear > a + 1.0) & (ds.normals[:, 2] > 0.5)].all()
    assert got.any()
    # the OCC reference (BRepExtrema on the tool's axis) agrees where it matters: conservative
    from cad_io.access import reference_tool

    ref = reference_tool(part.shape, vm.point[b][None], vm.normal[b][None], ds.normals, Tool(2 * a))[0]
    assert not (got & ~ref).any()
    assert got.sum() >= 0.5 * ref.sum()  # measured 14 of 24: the losses lie at grazing tilts
    # on the surface samples the slack is gone: as many directions as OCC's tool keeps (to
    # one), within 0.15 mm of the closed form (the ball sits on the floor sample nearest the
    # voxel's mean point, up to a sample step away)
    from cad_io.access import surface_samples

    smp = surface_samples(part, vm.step)
    As = accessibility(vm, vg, Tool(2 * a), samples=(smp.points, smp.normals, smp.face))
    got_s = to_bool(As[b], ds.k)
    assert got_s.sum() > got.sum() and got_s.sum() >= ref.sum() - 1
    assert not (got_s & across & (clear < a - 0.15)).any()
    assert got_s[across & (clear > a + 0.15) & (ds.normals[:, 2] > 0.5)].all()


@pytest.fixture(scope="module")
def undercut(tmp_path_factory):
    """A base 30 x 20 x 4, a wall x in [0, 4] up to z = 14, an overhang x in [0, 20], z in [10, 14]."""
    base = cq.Workplane("XY").box(30, 20, 4, centered=(False, True, False)).translate((-5, 0, 0))
    wall = cq.Workplane("XY").box(4, 20, 10, centered=(False, True, False)).translate((0, 0, 4))
    over = cq.Workplane("XY").box(20, 20, 4, centered=(False, True, False)).translate((0, 0, 10))
    part = _write(base.union(wall).union(over), tmp_path_factory.mktemp("undercut") / "undercut.step")
    from cad_io.access import voxelize

    vm = voxelize(part, 0.5, q=4)
    return part, vm, global_visibility(vm)


@pytest.mark.slow
def test_undercut_hidden_from_above_seen_from_the_side(undercut):
    part, vm, vg = undercut
    ds = vm.directions
    b = vm.voxel_of([[12.0, 0.0, 4.0 + 1e-9]])[0]
    got = to_bool(vg[b], ds.k)
    assert not got[ds.index("+z")]
    # closed form: from (12, 0, 4) a ray leaves under the overhang's edge (x = 20, z = 10) when
    # its rise over the 8 mm run stays below 6 mm and it is not caught by the side openings
    n = ds.normals
    side = (n[:, 0] > 0.3) & (np.abs(n[:, 1]) < 0.3 * n[:, 0]) & (n[:, 2] > 0.15)
    rise = 8.0 * n[:, 2] / np.maximum(n[:, 0], 1e-9)
    assert got[side & (rise < 6.0 - 1.5)].all()  # free with a margin of three voxels
    assert not (got & (n[:, 0] > 0) & (np.abs(n[:, 1]) < 0.05) & (rise > 6.0 + 1.0)).any()
    A = accessibility(vm, vg, Tool(3.0))
    v = three_axis(vm, A)
    # the floor under the overhang (16 x 20 mm, less a ball radius by the wall) is not 3-axis
    assert v["area_other"] + v["area_inaccessible"] > 16 * 20


def test_voxel_map_against_occ_rays(slot):
    """Thin rays from random surface points: the map never frees a blocked ray, and agrees on most."""
    from cad_io.access import agreement

    part, vm, vg = slot
    from zmap.access.voxelmap import AccessResult

    res = AccessResult(vm=vm, vg=vg, amap=vg, tool=Tool(4.0), verdict={}, setups=[], seconds={})
    ag = agreement(part, res, n_points=12, seed=3)
    assert ag["voxel_only_far"] == 0
    assert ag["agree_share"] > 0.95


def test_points_on_edges_take_their_faces_piece(slot):
    """On the slot's edges (voxels where two faces meet) a surface point gets its own face's
    piece's V'_g, which holds more directions than the voxel's (the AND over both faces), and
    the map with pieces still never frees a blocked ray."""
    from cad_io.access import agreement, point_visibility, surface_samples
    from zmap.access.directions import count
    from zmap.access.voxelmap import AccessResult

    part, vm, vg = slot
    vg2, vp = global_visibility(vm, pieces=True)
    assert (vg2 == vg).all() and len(vp) == len(vm.pieces.voxel) > 0
    res = AccessResult(vm=vm, vg=vg, amap=vg, tool=Tool(4.0), verdict={}, setups=[], seconds={}, vg_pieces=vp)
    p = vm.pieces
    got = point_visibility(res, p.voxel, p.face)
    assert (got == vp).all()
    plain = np.flatnonzero(vm.surface >= 0)[:50]
    assert (point_visibility(res, plain, vm.surface[plain]) == vg[plain]).all()
    assert (count(vp) > count(vg[p.voxel])).mean() > 0.5
    s = surface_samples(part, vm.step)
    on_edge = vm.surface[vm.voxel_of(s.points)] < 0
    assert on_edge.any()
    ag = agreement(part, res, n_points=12, seed=3)
    plain_ag = agreement(part, AccessResult(vm=vm, vg=vg, amap=vg, tool=Tool(4.0), verdict={}, setups=[],
                                            seconds={}), n_points=12, seed=3)
    assert ag["voxel_only_far"] == 0 and ag["agree_share"] >= plain_ag["agree_share"]


@pytest.mark.slow
def test_edge_points_take_their_faces_access_and_stay_conservative(slot):
    """A' of the pieces: a point on the slot's edges is answered for its own face's ball, never
    freer than OCC's tool there (BRepExtrema on the tool's axis), and the voxel's answer is the
    directions its pieces share."""
    from cad_io.access import point_access, reference_tool
    from zmap.access.directions import count
    from zmap.access.voxelmap import AccessResult

    part, vm, vg = slot
    vg2, vp = global_visibility(vm, pieces=True)
    tool = Tool(3.0)
    amap, ap = accessibility(vm, vg2, tool, pieces=True)
    res = AccessResult(vm=vm, vg=vg2, amap=amap, tool=tool, verdict={}, setups=[], seconds={}, vg_pieces=vp,
                       amap_pieces=ap)
    p = vm.pieces
    assert (point_access(res, p.voxel, p.face) == ap).all()
    plain = np.flatnonzero(vm.surface >= 0)[:50]
    assert (point_access(res, plain, vm.surface[plain]) == amap[plain]).all()
    crease = np.flatnonzero(vm.crease[p.voxel] & (count(ap) > 0))
    assert len(crease) > 0
    pick = crease[np.linspace(0, len(crease) - 1, 4).astype(int)]
    ref = reference_tool(part.shape, p.point[pick], p.normal[pick], vm.directions.normals, tool)
    got = to_bool(ap[pick], vm.directions.k)
    assert not (got & ~ref).any() and got.sum() >= 0.5 * ref.sum()  # measured 210 of 360
    # the losses lie at grazing tilts: every free direction within 40 degrees of the normal is kept
    steep = (p.normal[pick] @ vm.directions.normals.T) > np.cos(np.radians(40.0))
    assert got[ref & steep].all()


def test_bad_input(slot, tmp_path):
    from cad_io.access import analyse, voxelize
    from cad_io.step import read_step

    part = slot[0]
    with pytest.raises(AccessModelError, match="voxel size d must be a positive"):
        voxelize(part, 0.0)
    with pytest.raises(AccessModelError, match="voxel size d must be a positive"):
        voxelize(part, -0.5)
    with pytest.raises(AccessModelError, match=r"d' must be positive and smaller than the voxel d = 0.5"):
        voxelize(part, 0.5, step=0.5)
    with pytest.raises(AccessModelError, match="q must be an integer >= 1, got 0"):
        voxelize(part, 0.5, q=0)
    with pytest.raises(AccessModelError, match="tool diameter 60 mm is larger than the part"):
        analyse(part, d=0.5, q=1, tool=Tool(60.0))
    tess = read_step(STEP_DATA / "nist_ftc_08_asme1_ap242-2.stp")
    with pytest.raises(AccessModelError, match="no face has an exact surface"):
        voxelize(tess, 1.0)


@pytest.mark.slow
def test_analyse_without_refinement_is_the_voxels_cast(slot):
    """``analyse(refine=False)`` runs the paper's casting alone (no half-voxel maps), and the
    refined map holds every direction it keeps (the refinement only frees)."""
    from cad_io.access import analyse

    part = slot[0]
    plain = analyse(part, d=1.0, q=2, tool=Tool(4.0), refine=False)
    fine = analyse(part, d=1.0, q=2, tool=Tool(4.0))
    assert plain.vg_fine is None and fine.vg_fine is not None
    assert np.array_equal(plain.vg & fine.vg, plain.vg)
    assert np.array_equal(plain.amap & fine.amap, plain.amap)


def test_command_checks_its_options_before_the_analysis(tmp_path, capsys):
    """A bad --grid or --rays is refused before the part is read (not after minutes of
    analysis), and nothing is written."""
    from zmap.cli import main

    src = tmp_path / "block.step"
    cq.exporters.export(cq.Workplane("XY").box(10, 10, 5), str(src))
    out = tmp_path / "block.access.npz"
    for opt, val, msg in (("--grid", "0", "--grid must be a positive number of mm, got 0.0"),
                          ("--rays", "0", "--rays must be an integer >= 1, got 0")):
        assert main(["access", str(src), opt, val, "-o", str(out), "--no-png"]) != 0
        err = capsys.readouterr().err
        assert msg in err and "reading" not in err  # refused before the part was read
    assert not list(tmp_path.glob("*.npz")) and not list(tmp_path.glob(".tmp-*"))


def test_command_without_refinement(slot, tmp_path):
    """``--no-refine --rays 1``: the paper's casting alone, at a line per voxel edge; the map
    is written without half-voxel maps."""
    import json

    from zmap.cli import main

    src = tmp_path / "slot.step"
    cq.exporters.export(cq.Workplane("XY").box(LX, LY, H).translate((0, 0, -H / 2))
                        .cut(cq.Workplane("XY").box(W, LY + 10, D).translate((0, 0, -D / 2))), str(src))
    out = tmp_path / "slot.access.npz"
    rc = main(["access", str(src), "--voxel", "1", "--q", "2", "--tool", "ball:4", "--no-refine", "--rays", "1",
               "--no-png", "-o", str(out)])
    assert rc == 0
    with np.load(out) as z:
        assert "fine_vg" not in z.files and z["amap"].shape[1] == 2
        assert 0 < json.loads(bytes(z["header"]).decode())["verdict"]["share"] < 1


def test_command_on_a_zmap_file(tmp_path, capsys):
    """``zmap access`` on a saved z-map: the top-most surface with the material below it; its
    per-node counts say a 6 mm ball reaches a 2 mm slot's floor from no direction and the
    plateau from the upper hemisphere; ``--solid closed`` is refused before anything is read."""
    import json

    from zmap import ZMap
    from zmap.cli import main

    src = ZMap.from_function(lambda x, y: np.where(abs(x - 10) < 1, -5.0, 0.0), (0, 0, 20, 20), 0.25).save(
        tmp_path / "slot.zmap.npz")
    out = tmp_path / "slot.access.npz"
    assert main(["access", str(src), "--solid", "closed", "-o", str(out), "--no-png"]) != 0
    assert "not a closed shell" in capsys.readouterr().err and not out.exists()
    rc = main(["access", str(src), "--voxel", "0.5", "--q", "2", "--tool", "ball:6", "--grid", "2", "--no-png",
               "-o", str(out)])
    assert rc == 0
    with np.load(out) as z:
        head = json.loads(bytes(z["header"]).decode())
        assert head["node_grid"] == 2.0 and z["node_count"].shape == (11, 11)
        assert (z["node_count"][5, 1:-1] == 0).all()  # x = 10: the slot's floor
        assert (z["node_count"][2, 1:-1] == 40).all()  # x = 4: the plateau, k / 2 directions
    assert "below the zmap's surface" in capsys.readouterr().out


@pytest.mark.slow
def test_command_end_to_end(slot, tmp_path):
    import json

    from zmap.cli import main

    src = tmp_path / "slot.step"
    cq.exporters.export(cq.Workplane("XY").box(LX, LY, H).translate((0, 0, -H / 2))
                        .cut(cq.Workplane("XY").box(W, LY + 10, D).translate((0, 0, -D / 2))), str(src))
    out = tmp_path / "slot.access.npz"
    rc = main([ "access", str(src), "--voxel", "1", "--q", "2", "--tool", "ball:4", "--holder", "12x20",
               "--grid", "2", "-o", str(out)])
    assert rc == 0 and out.exists()
    for suffix in ("count", "setups", "sphere"):
        assert (tmp_path / f"slot_{suffix}.png").stat().st_size > 10_000
    with np.load(out) as z:
        head = json.loads(bytes(z["header"]).decode())
        assert head["format"] == "zmap.access" and head["q"] == 2 and z["amap"].shape[1] == 2
        assert 0 < head["verdict"]["share"] < 1
        assert z["node_count"].shape == (16, 11) and head["node_grid"] == 2.0
        has = z["node_voxel"] >= 0
        assert has.mean() > 0.95  # nodes on the box's far edges may fall just outside the voxels
        assert (z["node_count"][has] == z["n_access"][z["node_voxel"][has]]).all()
        assert z["fine_vg"].shape == (len(z["fine_voxel"]), 2) and len(z["fine_octant"]) == len(z["fine_face"]) > 0
        assert z["piece_amap"].shape == z["piece_vg"].shape
    assert not list(tmp_path.glob(".tmp-*"))


@pytest.mark.slow
def test_tool_map_against_occ_tool(slot):
    """The pipeline's A' (the tool tested on surface samples) against OCC's ball, shank and
    holder on random points of the slot: nothing freed that OCC blocks beyond one voxel, and
    nearly every pair the same."""
    from cad_io.access import agreement, analyse

    part = slot[0]
    res = analyse(part, d=0.5, q=3, tool=Tool(3.0, stickout=8.0, holder_diameter=10.0, holder_length=20.0))
    assert res.amap_pieces is not None and len(res.amap_pieces) == len(res.vm.pieces.voxel)
    ag = agreement(part, res, n_points=4, seed=1, tool=True)
    assert ag["voxel_only_far"] == 0 and ag["agree_share"] >= 0.97  # measured 0.981 (720 pairs; 3 freed within a voxel)


@pytest.mark.slow
def test_refined_map_against_occ_rays(slot):
    """The refined map (half-voxel pieces cast again where the voxel's cylinder is blocked):
    a surface point gets its half-voxel piece's bits, which hold its piece's and its voxel's;
    against the OCC thin rays it agrees at least as often as the plain map and never frees a
    ray blocked farther than a voxel."""
    from cad_io.access import agreement, point_visibility, surface_samples
    from zmap.access.voxelmap import AccessResult

    part, vm, vg = slot
    vb, vp, vf = global_visibility(vm, pieces=True, refine=True)
    assert not (vg & ~vb).any() and len(vf) == len(vm.fine.voxel)
    res = AccessResult(vm=vm, vg=vb, amap=vb, tool=Tool(4.0), verdict={}, setups=[], seconds={}, vg_pieces=vp,
                       vg_fine=vf)
    s = surface_samples(part, vm.step)
    v = vm.voxel_of(s.points)
    pick = np.flatnonzero(v >= 0)[::997]
    got = point_visibility(res, v[pick], s.face[pick], s.points[pick])
    base = point_visibility(res, v[pick], s.face[pick])
    assert not (base & ~got).any() and (got != base).any()
    f = vm.fine
    nf = int(f.face.max()) + 1
    keys = (f.voxel * 8 + f.octant) * nf + f.face
    half = np.clip(np.floor(2 * (s.points[pick] - vm.origin) / vm.d).astype(int) - 2 * vm.ijk[v[pick]], 0, 1)
    at = np.searchsorted(keys, (v[pick] * 8 + (half[:, 0] * 2 + half[:, 1]) * 2 + half[:, 2]) * nf + s.face[pick])
    assert (got == vf[at]).all()
    ag = agreement(part, res, n_points=12, seed=3)
    plain = agreement(part, AccessResult(vm=vm, vg=vg, amap=vg, tool=Tool(4.0), verdict={}, setups=[], seconds={},
                                         vg_pieces=global_visibility(vm, pieces=True)[1]), n_points=12, seed=3)
    assert ag["voxel_only_far"] == 0 and ag["agree_share"] >= plain["agree_share"]


@pytest.mark.slow
def test_open_die_face_three_axis_verdict_against_occ(tmp_path):
    """An open surface model (the cornetta relief of bug27693_cornetta-step.stp, a mould core,
    less its block's bottom and outer walls: free boundary edges, no solid) gets the material
    below its top surface, and its 3-axis verdict agrees with OCC's tool (the ball's centre
    outside that material) on >= 99 % of points, never freeing one OCC blocks."""
    from cad_io.access import agreement, analyse, top_faces
    from cad_io.step import read_step

    _, kept, left = top_faces(STEP_DATA / "bug27693_cornetta-step.stp", tmp_path / "die.step")
    assert kept > 0 and left > 0
    part = read_step(tmp_path / "die.step")
    assert any(e.is_boundary for e in part.edges)
    res = analyse(part, d=1.0, q=2, tool=Tool(6.0))
    assert res.vm.solid == "below" and "free boundary edges" in res.vm.solid_note
    assert "below the top surface" in res.summary()
    ag = agreement(part, res, n_points=200, seed=0, tool=True, axis="+z")
    assert ag["voxel_only"] == 0 and ag["agree_share"] >= 0.99


def test_thin_rib_voxels_uncertain_and_never_freed_where_occ_blocks(tmp_path):
    """A block with a rib thinner than the voxel (0.3 mm at d = 0.5): the part does not fail,
    the rib's voxels are uncertain, and neither their thin rays nor their tool map frees a
    (point, direction) pair that OCC finds blocked."""
    from cad_io.access import (analyse, point_access, point_visibility, reference_tool, reference_visibility,
                               surface_samples)
    from zmap.access.directions import to_bool

    blk = (cq.Workplane("XY").box(20, 12, 6).translate((0, 0, -3))
           .union(cq.Workplane("XY").box(0.3, 8, 5).translate((0, 0, 2.5))))
    part = _write(blk, tmp_path / "rib.step")
    res = analyse(part, d=0.5, q=1, tool=Tool(3.0))
    vm, ds = res.vm, res.vm.directions
    s = surface_samples(part, vm.step)
    rib = (np.abs(s.points[:, 0]) < 0.2) & (s.points[:, 2] > 0.6)
    vox = vm.voxel_of(s.points)
    # the rib's two long sides, off the block's top layer and the rib's own top
    sides = rib & (np.abs(s.normals[:, 0]) > 0.9) & (s.points[:, 2] < 4.4) & (np.abs(s.points[:, 1]) < 3.6)
    assert vm.uncertain[vox[sides]].all() and 0 < vm.uncertain_info["share"] < 0.25
    pick = np.flatnonzero(rib)[np.random.default_rng(0).choice(int(rib.sum()), 8, replace=False)]
    pts, nrm, fc, vb = s.points[pick], vm.orient(s.points[pick], s.normals[pick], s.face[pick]), s.face[pick], vox[pick]
    free, _ = reference_visibility(part.shape, pts, ds.normals)
    assert not (to_bool(point_visibility(res, vb, fc, pts), ds.k) & ~free).any()
    fits = reference_tool(part.shape, pts, nrm, ds.normals, res.tool)
    mine = to_bool(point_access(res, vb, fc), ds.k)
    assert not (mine & ~fits).any()


def test_agreement_of_no_points_is_refused_not_nan(sample_data):
    from cad_io.access import agreement, analyse
    from cad_io.step import read_step

    part = read_step(sample_data / "boss.step")
    res = analyse(part, d=2.0, q=2, tool=Tool(6.0))
    assert set(res.stats) == {"refine", "tool"} and res.stats["tool"]["scanned"] >= 0
    with pytest.raises(ValueError, match="n_points must be at least 1"):
        agreement(part, res, n_points=0)


@pytest.mark.slow
def test_a_design_never_reaches_from_above_where_the_exact_part_does_not():
    """The same part's access from its faces (cad_io) and as a design that gives heights (its
    exact top-most heights, and a z-map sampled from it): from +z, the design path is never
    less cautious than the faces, and agrees at most nodes (it is more cautious beside walls,
    where a height field's wall is a steep stretch between two samples)."""
    import cad_io
    from cad_io.access import analyse
    from zmap.access import analyse_design, node_directions

    part = cad_io.read_step(DATA / "pocket.step")  # a pocket with vertical walls in a block
    tool = Tool(6.0)
    b = part.bbox
    X, Y = np.meshgrid(np.arange(b[0] + 3, b[3] - 3, 1.0), np.arange(b[1] + 3, b[4] - 3, 1.0), indexing="ij")

    def from_above(result):
        vox, _ = node_directions(result.vm, result.amap, X, Y)
        up = result.vm.directions.index("+z")
        return (vox >= 0) & to_bool(result.amap, result.vm.directions.k)[np.maximum(vox, 0), up]

    faces = from_above(analyse(part, d=1.0, q=2, tool=tool))
    for design in (part, cad_io.sample(part, 0.25)):
        heights = from_above(analyse_design(design, d=1.0, q=2, tool=tool))
        assert not (heights & ~faces).any(), np.column_stack([X[heights & ~faces], Y[heights & ~faces]])[:5]
        assert (heights == faces).mean() > 0.9


def test_a_part_sampled_for_its_heights_first_still_maps():
    """The height sampler meshes a part more finely, with long thin triangles on its planes
    (a 38 mm wedge 0.45 mm wide on boss.step's top plane), which the face lattice samples only
    in their middles; OCC kept that mesh and handed it back to a coarser triangulation, and
    the access pipeline on the same part afterwards (a notebook that drops a cutter first)
    found its shell open. Now the map is the fresh part's."""
    import cad_io
    from cad_io.access import analyse
    from zmap.design import as_design

    fresh = analyse(cad_io.read_step(DATA / "boss.step"), d=1.0, q=2, tool=Tool(6.0))
    part = cad_io.read_step(DATA / "boss.step")
    as_design(part).heights(np.array([0.0]), np.array([0.0]))
    after = analyse(part, d=1.0, q=2, tool=Tool(6.0))
    assert after.vm.solid == fresh.vm.solid == "closed"
    assert after.vm.n_interior == fresh.vm.n_interior and np.array_equal(after.amap, fresh.amap)
