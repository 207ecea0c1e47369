"""cad_io.mesh.triangulate: BRepMesh meshes with NURBS uv, tessellated faces, geomdl grids."""

from __future__ import annotations

import numpy as np
import pytest

from cad_io.mesh import triangulate
from cad_io.nurbs import evaluate
from cad_io.step import read_step
from tests.conftest import DATA

cq = pytest.importorskip("cadquery")


def _node_error(face, mesh=None) -> np.ndarray:
    m = face.mesh if mesh is None else mesh
    return np.linalg.norm(evaluate(face.surface, m.uv[:, 0], m.uv[:, 1])[:, 0] - m.nodes,
                          axis=1)


def _chord_error(face, n_per_triangle: int = 1) -> float:
    """Distance from triangle centroids to the surface at the centroid's mean uv."""
    m = face.mesh
    t = m.triangles
    cen = m.nodes[t].mean(axis=1)
    uvc = m.uv[t].mean(axis=1)
    from cad_io._nurbs_kernels import project_points
    from cad_io.nurbs import pack

    uv = np.empty_like(uvc)
    dist = np.empty(len(uvc))
    project_points(*pack([face.surface]).arrays(), 0, cen, np.ascontiguousarray(uvc), 0.0,
                   uv, dist)
    return float(dist.max())


@pytest.fixture(scope="module")
def analytic_part(tmp_path_factory):
    path = tmp_path_factory.mktemp("mesh") / "analytic.step"
    solid = (cq.Workplane().box(30, 20, 10).edges("|Z").fillet(3)
             .faces(">Z").workplane().hole(6)
             .union(cq.Workplane().sphere(4).translate((8, 0, 5)))
             .union(cq.Solid.makeTorus(6, 1.5).translate(cq.Vector(0, 0, -5))))
    cq.exporters.export(solid, str(path))
    part = read_step(path)
    triangulate(part, 0.01)
    return part


def test_every_face_meshed_with_exact_uv(analytic_part):
    for f in analytic_part.faces:
        m = f.mesh
        assert m is not None and m.deflection == 0.01
        assert m.nodes.shape[1] == 3 and m.triangles.dtype == np.int32
        assert m.triangles.min() >= 0 and m.triangles.max() < len(m.nodes)
        assert m.uv.shape == (len(m.nodes), 2)
        assert _node_error(f).max() < 1e-6, (f.index, f.kind)


def test_chordal_error_within_deflection(analytic_part):
    for f in analytic_part.faces:
        assert _chord_error(f) <= 0.01 * 1.05, (f.index, f.kind)


def test_triangles_face_outward(analytic_part):
    for f in analytic_part.faces:
        m = f.mesh
        a, b, c = (m.nodes[m.triangles[:, k]] for k in range(3))
        tn = np.cross(b - a, c - a)
        ok = np.linalg.norm(tn, axis=1) > 1e-12
        uvc = m.uv[m.triangles].mean(axis=1)[ok]
        d = evaluate(f.surface, uvc[:, 0], uvc[:, 1], derivs=1)
        sn = np.cross(d[:, 1], d[:, 2]) * (-1 if f.reversed else 1)
        good = np.linalg.norm(sn, axis=1) > 1e-9
        agree = np.einsum("ij,ij->i", tn[ok][good], sn[good]) > 0
        assert agree.mean() > 0.99, (f.index, f.kind, agree.mean())


def test_box_mesh_is_closed_and_outward(tmp_path):
    path = tmp_path / "box.step"
    cq.exporters.export(cq.Workplane().box(4, 6, 8), str(path))
    part = read_step(path)
    triangulate(part, 0.05)
    vol = 0.0
    for f in part.faces:
        m = f.mesh
        a, b, c = (m.nodes[m.triangles[:, k]] for k in range(3))
        vol += np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0
    assert abs(vol - 4 * 6 * 8) < 1e-9  # outward triangles enclose +volume


def test_tessellated_only_faces(sample_data):
    part = read_step(sample_data / "step" / "nist_ftc_08_asme1_ap242-2.stp")
    triangulate(part, 0.1)
    assert all(f.mesh is not None and f.mesh.uv is None for f in part.faces)
    assert sum(len(f.mesh.triangles) for f in part.faces) == 3377
    b = np.array(part.bbox)
    for f in part.faces:
        assert np.all(f.mesh.nodes >= b[:3] - 1e-6) and np.all(f.mesh.nodes <= b[3:] + 1e-6)


def test_faces_meshed_alone_leave_the_part_as_it_is(sample_data):
    """``mesh_faces_alone`` meshes copies: the part's meshes and OCC triangulations stay,
    each face's mesh is the same whichever other faces are asked for, and a tessellated-only
    face keeps its stored triangles (a copy would drop them)."""
    from cad_io.mesh import mesh_faces_alone

    part = read_step(sample_data / "step" / "featuretype.STEP")
    triangulate(part, 0.5)
    before = [(len(f.mesh.triangles), f.mesh) for f in part.faces]
    one = mesh_faces_alone(part, [3], 0.05)[0]
    several = mesh_faces_alone(part, [7, 3, 11], 0.05)
    assert np.array_equal(one.nodes, several[1].nodes) and np.array_equal(one.triangles, several[1].triangles)
    assert len(one.triangles) > before[3][0] and one.uv is not None and _node_error(part.faces[3], one).max() < 1e-6
    assert all(f.mesh is m for f, (_, m) in zip(part.faces, before))
    triangulate(part, 0.5)  # the OCC faces kept their 0.5 mm triangulation: the same meshes again
    assert [len(f.mesh.triangles) for f in part.faces] == [n for n, _ in before]
    tess = read_step(sample_data / "step" / "nist_ftc_08_asme1_ap242-2.stp")
    triangulate(tess, 0.1)
    got = mesh_faces_alone(tess, range(len(tess.faces)), 0.01)
    assert all(g is f.mesh for g, f in zip(got, tess.faces))


def test_real_part_uv_within_file_tolerance(sample_data):
    from OCP.BRep import BRep_Tool
    from OCP.TopAbs import TopAbs_EDGE, TopAbs_VERTEX

    part = read_step(sample_data / "step" / "featuretype.STEP")
    triangulate(part, 0.05)
    for f in part.faces:
        tol = max(BRep_Tool.MaxTolerance_s(f.topo, TopAbs_VERTEX),
                  BRep_Tool.MaxTolerance_s(f.topo, TopAbs_EDGE), 1e-6)
        assert _node_error(f).max() <= 1.5 * tol, (f.index, f.kind)


def test_geomdl_grid_within_deflection():
    from geomdl import NURBS

    s = NURBS.Surface()
    s.degree_u, s.degree_v = 2, 3
    s.ctrlpts_size_u, s.ctrlpts_size_v = 4, 5
    rng = np.random.default_rng(0)
    pts = [[2.0 * i, 2.0 * j, float(rng.uniform(-1, 1))] for i in range(4) for j in range(5)]
    s.ctrlpts = pts
    s.weights = rng.uniform(0.5, 2.0, 20).tolist()
    s.knotvector_u = [0, 0, 0, 0.5, 1, 1, 1]
    s.knotvector_v = [0, 0, 0, 0, 0.4, 1, 1, 1, 1]
    from cad_io.geomdl_io import from_geomdl

    part = from_geomdl(s)
    triangulate(part, 0.002)
    f = part.faces[0]
    assert _node_error(f).max() < 1e-12
    assert _chord_error(f) <= 0.002


def test_bad_deflection(analytic_part):
    with pytest.raises(ValueError, match="deflection must be a positive"):
        triangulate(analytic_part, 0.0)


def test_located_assembly_parts(tmp_path):
    """Faces placed by assembly locations: world nodes, exact uv."""
    asm = cq.Assembly()
    asm.add(cq.Workplane().cylinder(4, 2), name="c",
            loc=cq.Location(cq.Vector(10, 20, 30), cq.Vector(1, 0, 0), 30))
    asm.add(cq.Workplane().box(1, 1, 1), name="b", loc=cq.Location(cq.Vector(-5, 0, 0)))
    path = tmp_path / "asm.step"
    asm.export(str(path))
    part = read_step(path)
    assert any(not f.topo.Location().IsIdentity() for f in part.faces)
    triangulate(part, 0.01)
    for f in part.faces:
        assert _node_error(f).max() < 1e-6
        lo, hi = np.array(f.bbox[:3]), np.array(f.bbox[3:])
        assert np.all(f.mesh.nodes >= lo - 1e-6) and np.all(f.mesh.nodes <= hi + 1e-6)
    cyl = next(f for f in part.faces if f.kind == "cylinder")
    # axis along z rotated 30 degrees about x, through (10, 20, 30), radius 2
    axis = np.array([0.0, -np.sin(np.pi / 6), np.cos(np.pi / 6)])
    rel = cyl.mesh.nodes - [10, 20, 30]
    radial = rel - np.outer(rel @ axis, axis)
    np.testing.assert_allclose(np.linalg.norm(radial, axis=1), 2.0, atol=1e-6)
    assert np.abs(rel @ axis).max() <= 2 + 1e-9


def _trj8_face(sample_data, index: int):
    part = read_step(sample_data / "step" / "trj8_b1-ec-214.stp")
    return part, part.faces[index]


@pytest.mark.slow
def test_trimmed_grid_covers_the_face_and_its_tolerance_band(sample_data):
    """trj8's face 22 (a degree 8 x 11 patch, edges of 0.22 mm, BRepMesh 0.55 mm off at
    10 um asked): the grid's nodes are on the surface, its triangles within the deflection,
    every point of the trimmed face lies in a kept cell, and the kept cells' own outline is
    at least ``reach`` (3D) beyond the trim loop wherever it is not the surface's edge."""
    from cad_io import _trim_kernels as K
    from cad_io.mesh import trimmed_grid_mesh

    _part, f = _trj8_face(sample_data, 22)
    reach = 0.25
    m = trimmed_grid_mesh(f, 0.01, reach)
    assert _node_error(f, m).max() < 1e-12
    assert m.deflection <= 0.01
    face = type(f)(**{**vars(f), "mesh": m})
    assert _chord_error(face) <= 0.01 + 1e-9
    loop = np.asarray(f.loops[0], dtype=np.float64)
    off = np.array([0, len(loop)], dtype=np.int64)
    # random points of the trimmed face: each inside a kept triangle in (u, v)
    u0, u1, v0, v1 = f.surface.domain
    rng = np.random.default_rng(0)
    us, vs = rng.uniform(u0, u1, 20_000), rng.uniform(v0, v1, 20_000)
    inside = np.empty(us.size, dtype=np.bool_)
    K.points_in_loops(us, vs, np.ascontiguousarray(loop), off, 0.0, inside)
    us, vs = us[inside], vs[inside]
    assert us.size > 1000
    tri_uv = m.uv[m.triangles]
    a, b, c = tri_uv[:, 0], tri_uv[:, 1], tri_uv[:, 2]
    det = (b[:, 1] - c[:, 1]) * (a[:, 0] - c[:, 0]) + (c[:, 0] - b[:, 0]) * (a[:, 1] - c[:, 1])
    covered = np.zeros(us.size, dtype=bool)
    for lo in range(0, us.size, 500):
        pu, pv = us[lo:lo + 500, None], vs[lo:lo + 500, None]
        w1 = ((b[:, 1] - c[:, 1]) * (pu - c[:, 0]) + (c[:, 0] - b[:, 0]) * (pv - c[:, 1])) / det
        w2 = ((c[:, 1] - a[:, 1]) * (pu - c[:, 0]) + (a[:, 0] - c[:, 0]) * (pv - c[:, 1])) / det
        covered[lo:lo + 500] = ((w1 >= -1e-12) & (w2 >= -1e-12) & (w1 + w2 <= 1 + 1e-12)).any(axis=1)
    assert covered.all(), int((~covered).sum())
    # the outline of the kept cells, off the surface's own edges, is beyond the band
    e = np.concatenate([m.triangles[:, [0, 1]], m.triangles[:, [1, 2]], m.triangles[:, [2, 0]]])
    e.sort(axis=1)
    key, cnt = np.unique(e[:, 0].astype(np.int64) * len(m.nodes) + e[:, 1], return_counts=True)
    outline = np.unique(np.concatenate([key[cnt == 1] // len(m.nodes), key[cnt == 1] % len(m.nodes)]))
    span = np.array([u1 - u0, v1 - v0])
    off_edge = outline[np.all((np.abs(m.uv[outline] - [u0, v0]) > 1e-9 * span)
                              & (np.abs(m.uv[outline] - [u1, v1]) > 1e-9 * span), axis=1)]
    assert off_edge.size > 0
    loop_xyz = evaluate(f.surface, loop[:, 0], loop[:, 1])[:, 0]
    d = np.linalg.norm(m.nodes[off_edge][:, None, :] - loop_xyz[None, :, :], axis=2).min(axis=1)
    assert d.min() >= reach, d.min()


@pytest.mark.slow
def test_trimmed_grid_pairs_few_triangles_a_point(sample_data):
    """The sampler meshes trj8's badly meshed faces with the trimmed grid: a point over face
    22 pairs with about one triangle, where BRepMesh's triangles, 0.55 mm off and widened by
    twice that, paired 28 (Newton then ran 55 us a pair: trj8's EZ build over 42 minutes)."""
    from cad_io import _sample_kernels as K
    from cad_io._sample_faces import _cached_face_set
    from cad_io._sample_points import _bins
    from cad_io.sampler import POINTS_DEFLECTION

    part, f = _trj8_face(sample_data, 22)
    fs = _cached_face_set(part, POINTS_DEFLECTION, "+z")
    rng = np.random.default_rng(1)
    x0, y0, _, x1, y1, _ = f.bbox
    x, y = rng.uniform(x0, x1, 5000), rng.uniform(y0, y1, 5000)
    counts = np.zeros(len(fs.tris), dtype=np.int64)
    K.count_pairs_xy(fs.nodes, fs.tris, fs.tri_margin, x, y, *_bins(x, y, fs), counts)
    on_face = fs.tri_face == 22
    per_point = counts[on_face].sum() / 5000
    assert 0.3 < per_point < 2.0, per_point


def test_a_part_meshes_the_same_at_a_deflection_whatever_was_meshed_before():
    """OCC keeps a shape's finer triangulation and hands it back to a coarser request; the
    part's mesh at a deflection is the same after a finer one as on a fresh part."""
    import cad_io
    from cad_io.mesh import triangulate

    fresh = cad_io.read_step(DATA / "boss.step")
    triangulate(fresh, 0.25)
    part = cad_io.read_step(DATA / "boss.step")
    triangulate(part, 0.01)
    triangulate(part, 0.25)
    for a, b in zip(fresh.faces, part.faces):
        assert np.array_equal(a.mesh.triangles, b.mesh.triangles) and np.allclose(a.mesh.nodes, b.mesh.nodes)
