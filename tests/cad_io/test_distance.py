"""distance_to_part against OCC's BRepExtrema_DistShapeShape."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from cad_io.distance import distance_to_part, occ_distance as _occ_distance
from cad_io.sampler import sample_points
from cad_io.step import read_step

DATA = Path(__file__).resolve().parents[2] / "data"


def _near_surface(part, n, seed):
    rng = np.random.default_rng(seed)
    b = np.array(part.bbox)
    x = rng.uniform(b[0], b[3], 4 * n)
    y = rng.uniform(b[1], b[4], 4 * n)
    z = sample_points(part, x, y)[0]
    ok = np.flatnonzero(np.isfinite(z))[:n]
    return np.c_[x[ok], y[ok], z[ok] + rng.uniform(-0.3, 0.3, ok.size)]


@pytest.mark.slow
@pytest.mark.parametrize("name", ["pocket", "boss"])
def test_matches_occ(name):
    part = read_step(DATA / f"{name}.step")
    pts = _near_surface(part, 200, 1)
    d = distance_to_part(part, pts)
    ref = _occ_distance(part.shape, pts)
    assert np.max(np.abs(d - ref)) <= 0.002  # the default mesh deflection bounds the fallback


@pytest.mark.slow
def test_real_part_matches_occ(sample_data):
    part = read_step(sample_data / "step" / "featuretype.STEP")
    pts = _near_surface(part, 100, 2)
    d = distance_to_part(part, pts, deflection=0.005)
    ref = _occ_distance(part.shape, pts)
    assert np.max(np.abs(d - ref)) <= 0.005


@pytest.mark.slow
def test_on_surface_is_zero_and_nan_rows():
    part = read_step(DATA / "pocket.step")
    d = distance_to_part(part, [[0.0, 0.0, 15.0], [0.0, 0.0, 16.0], [np.nan, 0.0, 0.0]])
    assert d[0] == pytest.approx(0.0, abs=1e-8)
    assert d[1] == pytest.approx(1.0, abs=1e-8)
    assert np.isnan(d[2])
    with pytest.raises(ValueError, match="shape"):
        distance_to_part(part, np.zeros((3, 2)))


@pytest.mark.slow
def test_dense_face_does_not_crowd_out_the_nearest_one():
    # Beside the pocket's corner torus a floor-fillet cylinder is meshed far more densely;
    # its samples used to fill all the nearest neighbours and the distance came out 0.044
    # where OCC gives 0.00038.
    part = read_step(DATA / "pocket.step")
    pts = np.array([[22.0441, 18.498, 15.4013], [-28.8087, 12.0374, 15.6071]])
    d = distance_to_part(part, pts, deflection=0.002)
    np.testing.assert_allclose(d, _occ_distance(part.shape, pts), atol=1e-6)


def test_spread_grows_with_area_not_with_the_longest_edge():
    # a 100 mm x 1 um sliver (a cylinder meshed at 0.5 um is made of them) used to get
    # (n+1)(n+2)/2 = 20,301 samples at n = 200; a lattice along and across needs ~2n
    from cad_io.distance import _spread

    nodes = np.array([[0.0, 0.0, 0.0], [100.0, 0.0, 0.0], [50.0, 0.001, 0.0], [0.0, 10.0, 0.0]])
    uv = nodes[:, :2].copy()
    xyz, uv_s, tri = _spread(nodes, uv, np.array([[0, 1, 2]]), 0.5)
    assert len(xyz) <= 2 * (200 + 1) + 1
    np.testing.assert_allclose(uv_s, xyz[:, :2])  # uv carried with the same weights
    # a fat triangle: every point of it within a spacing of a sample
    xyz, _, _ = _spread(nodes, uv, np.array([[0, 1, 3]]), 0.5)
    rng = np.random.default_rng(0)
    w = rng.dirichlet(np.ones(3), 2000)
    probe = w @ nodes[[0, 1, 3]]
    gap = np.min(np.linalg.norm(probe[:, None, :] - xyz[None, :, :], axis=2), axis=1)
    assert gap.max() <= 0.5
    assert len(xyz) <= 2.5 * (0.5 * 100 * 10) / 0.5**2


def test_confirm_with_occ_slack_sends_mesh_distances_near_the_threshold_to_occ():
    from cad_io.distance import confirm_with_occ

    part = read_step(DATA / "pocket.step")
    pts = np.array([[0.0, 0.0, 15.004], [0.0, 0.0, 15.004]])
    # both under-reported at 0.003 < 0.005; only the one flagged with a slack is re-measured
    d, n_occ, n_left = confirm_with_occ(part, pts, np.array([0.003, 0.003]), above=0.005, slack=[0.0, 0.0025])
    assert (n_occ, n_left) == (1, 0)
    np.testing.assert_allclose(d, [0.003, 0.004], atol=1e-9)


def test_own_tolerance_is_the_nearest_edges_in_the_file():
    from OCP.ShapeFix import ShapeFix_ShapeTolerance
    from OCP.TopAbs import TopAbs_EDGE

    from cad_io.distance import occ_distance_own_tolerance

    part = read_step(DATA / "pocket.step")
    # a point 0.1 mm out from the block's top edge at x = 50, z = 30 both ways, one 0.2 mm
    # out from the side face, and one above the pocket's floor
    pts = [[50.1, 0.0, 30.1], [50.2, 0.0, 15.0], [0.0, 0.0, 16.0]]
    d, t = occ_distance_own_tolerance(part.shape, pts)
    assert np.allclose(d, _occ_distance(part.shape, pts), rtol=0, atol=1e-12)
    assert np.allclose(d, [0.1 * np.sqrt(2), 0.2, 1.0], rtol=0, atol=1e-9) and np.all(t < 1e-3)
    ShapeFix_ShapeTolerance().SetTolerance(part.shape, 0.3, TopAbs_EDGE)  # as a badly toleranced file has it
    d2, t2 = occ_distance_own_tolerance(part.shape, pts)
    assert np.allclose(d2, d, rtol=0, atol=1e-12)
    assert t2[0] == pytest.approx(0.3) and d2[0] - t2[0] < 0  # within the edge's tolerance: on the shape
    assert np.all(t2[1:] < 1e-3)  # nearest a face's interior: the face's own tolerance


def test_band_distance_is_to_the_face_past_its_trim_curve_within_its_edges_tolerance():
    """A face whose edges carry 0.3 mm in the file holds the points on its surface up to
    0.3 mm past its trim curves (OCC's ray cast answers there, and so does the sampler),
    even beyond an edge of its own whose tolerance is tight: trj8 has points 0.27 mm past
    face 351's curve whose nearest edge carries 0.12 mm. The nearest sub-shape's tolerance
    alone does not count them."""
    from OCP.BRep import BRep_Tool
    from OCP.ShapeFix import ShapeFix_ShapeTolerance
    from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE
    from OCP.TopExp import TopExp, TopExp_Explorer
    from OCP.TopoDS import TopoDS
    from OCP.TopTools import TopTools_IndexedMapOfShape

    from cad_io.distance import occ_band_distance, occ_distance_own_tolerance

    part = read_step(DATA / "pocket.step")
    fmap = TopTools_IndexedMapOfShape()
    TopExp.MapShapes_s(part.shape, TopAbs_FACE, fmap)
    top = TopoDS.Face_s(fmap.FindKey(3))  # face 2: z = 30, x -50 .. 50, y -40 .. 40
    ex = TopExp_Explorer(top, TopAbs_EDGE)
    while ex.More():  # 0.3 mm on its edge at x = -50 only
        edge = TopoDS.Edge_s(ex.Current())
        p0 = BRep_Tool.Pnt_s(TopExp.FirstVertex_s(edge))
        p1 = BRep_Tool.Pnt_s(TopExp.LastVertex_s(edge))
        if abs(p0.X() + 50) < 1e-9 and abs(p1.X() + 50) < 1e-9:
            ShapeFix_ShapeTolerance().SetTolerance(edge, 0.3, TopAbs_EDGE)
        ex.Next()
    # on the top plane 0.2 mm past its edge at x = 50 (tolerance 1e-7); 0.05 above that;
    # 0.4 mm past it (beyond the band); over the pocket's floor (inside a face)
    pts = [[50.2, 0.0, 30.0], [50.2, 0.0, 30.05], [50.4, 0.0, 30.0], [0.0, 0.0, 16.0]]
    do, to = occ_distance_own_tolerance(part.shape, pts)
    assert np.allclose(np.maximum(do - to, 0.0)[:3], [0.2, np.hypot(0.2, 0.05), 0.4], atol=1e-9)
    d, w = occ_band_distance(part.shape, pts, do + 1e-3)
    # 0.4 mm past: not on the top face; the side face x = 50, 0.4 mm away, is the nearest
    np.testing.assert_allclose(d, [0.0, 0.05, 0.4, 1.0], atol=1e-9)
    np.testing.assert_allclose(w, [0.3, 0.3, 1e-7, 1e-7], rtol=1e-6)
    # only faces nearer than the reach given are looked for
    d0, w0 = occ_band_distance(part.shape, pts, do)
    assert np.isinf(d0[2:]).all() and (w0[2:] == 0).all()


def _segment_d2_reference(p, a, b):
    e = b - a
    ee = float(e @ e)
    t = 0.0 if ee == 0.0 else min(max(float((p - a) @ e) / ee, 0.0), 1.0)
    q = a + t * e
    return float((p - q) @ (p - q))


def _triangle_d_reference(p, a, b, c):
    """Slow, obvious: the plane foot where it falls inside a sound triangle, else the edges."""
    best = min(_segment_d2_reference(p, a, b), _segment_d2_reference(p, b, c), _segment_d2_reference(p, c, a))
    n = np.cross(b - a, c - a)
    nn = float(n @ n)
    if nn > 1e-12 * float((b - a) @ (b - a)) * float((c - a) @ (c - a)):
        q = p - (n @ (p - a)) / nn * n
        w = np.linalg.solve(np.c_[b - a, c - a, n], q - a)[:2]
        if w.min() >= 0 and w.sum() <= 1:
            best = min(best, float((p - q) @ (p - q)))
    return math.sqrt(best)


def test_mesh_distance_on_degenerate_triangles():
    """Zero-length edges, coincident and collinear vertices (BRepMesh leaves such triangles on
    some real parts) give the distance to what is left of the triangle, never a division by zero
    (a ZeroDivisionError inside the numba kernel, reported as a SystemError, stopped a report)."""
    from cad_io import _distance_kernels as K

    nodes = np.array([[0, 0, 0], [0, 0, 0], [1, 0, 0], [2, 0, 0], [1, 1, 0], [1, 1, 1e-300],
                      [1 + 1e-13, 0, 0], [0.5, 0.5, 0.5]], float)
    tris = np.array([[0, 1, 2],   # a zero-length edge: a segment
                     [1, 0, 4],   # the same, other order
                     [0, 2, 3],   # three collinear vertices
                     [0, 1, 1],   # one point three times
                     [4, 5, 2],   # a needle edge of 1e-300 mm
                     [2, 6, 7],   # an edge of 1e-13 mm
                     [0, 2, 4]],  # a sound triangle
                    np.int64)
    rng = np.random.default_rng(5)
    pts = np.vstack([rng.uniform(-1.5, 3.0, (200, 3)), nodes + rng.normal(0, 1e-3, nodes.shape),
                     [[0.5, 0.3, 1.0], [0.5, 0.0, 0.0], [1.0, 1.0, 0.0]]])
    out = np.empty(len(pts))
    for t in range(len(tris)):
        cand = np.full((len(pts), 1), t, dtype=np.int64)
        K.mesh_distance(pts, cand, nodes, tris, out)
        ref = [_triangle_d_reference(p, *nodes[tris[t]]) for p in pts]
        assert np.all(np.isfinite(out)), t
        assert np.max(np.abs(out - ref)) < 1e-7, t
    # several candidates, one of them missing (-1): the nearest counts
    cand = np.tile(np.array([-1, 0, 3, 4, 6], dtype=np.int64), (len(pts), 1))
    K.mesh_distance(pts, cand, nodes, tris, out)
    ref = [min(_triangle_d_reference(p, *nodes[tris[t]]) for t in (0, 3, 4, 6)) for p in pts]
    assert np.max(np.abs(out - ref)) < 1e-7


@pytest.mark.slow
def test_distance_to_part_with_degenerate_mesh_triangles():
    """A part whose face meshes carry degenerate triangles measures as it does without them."""
    import copy

    from cad_io.mesh import triangulate
    from cad_io.part import FaceMesh

    part = read_step(DATA / "pocket.step")
    triangulate(part, 0.01)
    pts = _near_surface(part, 300, 7)
    d0 = distance_to_part(part, pts, deflection=0.01)
    bad = copy.copy(part)
    bad.__dict__ = {k: v for k, v in part.__dict__.items() if not k.startswith("_")}  # no caches
    bad.faces = [copy.copy(f) for f in part.faces]
    for f in bad.faces:
        m = f.mesh
        t = m.triangles
        extra = np.c_[t[:, 0], t[:, 0], t[:, 1]]  # a zero-length edge on every triangle's first node
        flat = np.c_[t[:, 0], t[:, 1], t[:, 1]]
        f.mesh = FaceMesh(m.nodes, np.vstack([t, extra, flat]).astype(t.dtype), m.uv, m.deflection)
    d1 = distance_to_part(bad, pts, deflection=0.01)
    assert np.all(np.isfinite(d1)) and np.max(np.abs(d1 - d0)) < 1e-9


def test_kernels_never_raise_for_a_division_by_zero():
    """Every numba kernel of the sampler, the NURBS, the tiles and the EZ-map returns inf/NaN
    for a division by zero instead of raising from compiled code (error_model='numpy')."""
    import importlib

    from numba.core.registry import CPUDispatcher

    for name in ("cad_io._sample_kernels", "cad_io._trim_kernels", "cad_io._newton_kernels",
                 "cad_io._distance_kernels", "cad_io._nurbs_kernels", "cad_io._tiled_kernels",
                 "zmap.refine._ez_kernels", "zmap.refine._edge_kernels", "zmap.refine._thin_kernels",
                 "zmap.refine._coons_kernels", "zmap.refine._trace_kernels", "zmap.refine._split_kernels"):
        mod = importlib.import_module(name)
        kernels = [v for v in vars(mod).values() if isinstance(v, CPUDispatcher) and v.__module__ == name]
        assert kernels, name
        for k in kernels:
            assert k.targetoptions.get("error_model") == "numpy", f"{name}.{k.__name__}"
