"""Faces whose edges carry a large tolerance in the file (trj8_b1-ec-214: edges of
0.2-0.95 mm): the sampler's heights there are OCC's, and Newton answers them, not facets."""

from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("OCP")

from cad_io.sampler import sample_points  # noqa: E402
from cad_io.step import read_step  # noqa: E402

TRJ8 = Path(__file__).resolve().parents[2] / "data" / "step" / "trj8_b1-ec-214.stp"


def _bspline_face_file(path: Path) -> Path:
    """A 40 x 40 mm B-spline sheet, z = 5 + 4 sin(x/6) cos(y/7) through 9 x 9 points, as STEP."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.GeomAPI import GeomAPI_PointsToBSplineSurface
    from OCP.gp import gp_Pnt
    from OCP.STEPControl import STEPControl_AsIs, STEPControl_Writer
    from OCP.TColgp import TColgp_Array2OfPnt

    n = 9
    grid = TColgp_Array2OfPnt(1, n, 1, n)
    for i in range(n):
        for j in range(n):
            x, y = 40.0 * i / (n - 1), 40.0 * j / (n - 1)
            grid.SetValue(i + 1, j + 1, gp_Pnt(x, y, 5 + 4 * np.sin(x / 6) * np.cos(y / 7)))
    face = BRepBuilderAPI_MakeFace(GeomAPI_PointsToBSplineSurface(grid).Surface(), 1e-6).Face()
    # OCC's writer messages go to fd 1, which pytest captures
    writer = STEPControl_Writer()
    writer.Transfer(face, STEPControl_AsIs)
    writer.Write(str(path))
    return path


def test_newton_answers_where_brepmesh_misses_the_deflection(tmp_path):
    """BRepMesh meshes a face at about twice its tolerance whatever deflection is asked: with
    0.3 mm on the sheet's edges, 666 triangles 0.64 mm off the surface at a requested 5 um.
    The layer check took the requested deflection, refused Newton's exact answers, and 113 of
    200 points came from facets up to 0.52 mm off (trj8's e-points: 53.8 M of 95 M)."""
    from OCP.ShapeFix import ShapeFix_ShapeTolerance
    from OCP.TopAbs import TopAbs_SHAPE

    from cad_io.raycast import RayCaster

    import dataclasses

    from cad_io.step import _edge_tolerance

    part = read_step(_bspline_face_file(tmp_path / "sheet.step"))
    ShapeFix_ShapeTolerance().SetTolerance(part.shape, 0.3, TopAbs_SHAPE)
    # the part records its faces' edge tolerances as read: record the new ones, as a file
    # with these tolerances would give them
    part = dataclasses.replace(part, faces=[dataclasses.replace(f, tolerance=_edge_tolerance(f.topo))
                                            for f in part.faces])
    assert min(f.tolerance for f in part.faces) >= 0.3
    rng = np.random.default_rng(0)
    x, y = rng.uniform(1, 39, 200), rng.uniform(1, 39, 200)
    z, _, how = sample_points(part, x, y, deflection=0.005)
    zr, _ = RayCaster(part.shape)(x, y)
    assert (how == 1).all(), np.bincount(how, minlength=3)
    np.testing.assert_allclose(z, zr, rtol=0, atol=1e-6)


@cache
def _trj8():
    from cad_io.raycast import RayCaster, read_shape

    return read_step(TRJ8), RayCaster(read_shape(TRJ8))


#: (x, y) seen from +z on trj8 where a face's claim within its edges' tolerance decides:
#: 37 (edges 0.23 mm) 0.2 mm outside its loop over 355, 0.04 mm lower, and OCC's face
#: classifier says out (3D distance to its edges 0.33 > 0.23); 365 over 390 41 mm below,
#: 1.75e-3 from its loop in uv, just beyond OCC's 1.73e-3; 37, 42 and 320 within the band
#: (OCC sees them: 0.07-0.14 mm outside, their edges 0.11-0.22 mm away); 122 beyond its uv
#: bounds (OCC sees no surface there); 27, a plane at z = 5, under a ray on which face 372's
#: intersector throws (the reference lost the whole ray)
BAND_POINTS = [(126.9939, -32.0), (76.7439, -16.5), (67.7439, 16.0), (123.2439, 24.5),
               (69.7439, -16.0), (160.7439, -33.0), (142.2439, 27.0), (221.2439, -64.0),
               (-9.2561, 15.5), (-13.7561, -12.0)]


@pytest.mark.slow
def test_trj8_heights_within_edge_tolerance_are_occs():
    """Where trj8's faces overlap within their edges' tolerance, the top-most face is the
    one OCC's ray cast counts on its face (hits outside the trim curves within the uv
    resolution of the tolerance and within the tolerance of an edge curve): the slack
    widened to the tolerance gave 0.04 and 41 mm differences, no slack 0.017 mm."""
    part, caster = _trj8()
    x, y = np.array(BAND_POINTS).T
    z, face, how = sample_points(part, x, y)
    zr, fr = caster(x, y)
    assert np.isfinite(zr).all()
    assert (how == 1).all()
    np.testing.assert_allclose(z, zr, rtol=0, atol=1e-6)
    assert face[0] == 355 and face[3] == 390 and face[4] == 37 and face[8] == 27


#: (x, y) on trj8's steep faces 361, 352 and 316 (edges 1e-3 and 3e-3 mm, within the 5 um
#: deflection): BRepMesh meshes 361 in 66 triangles up to 0.06 mm off its surface, the layer
#: check refused Newton's answers 0.18 mm above the facet (|n_z| 0.32, not a wall), and the
#: facets answered 0.07 mm off the face in 3D
TIGHT_FACE_POINTS = [(133.99063, -27.52550), (133.97269, -27.54371), (182.46046, -23.83661),
                     (182.88922, 23.62616), (183.61004, -23.79480)]


@pytest.mark.slow
def test_trj8_faces_brepmesh_misses_with_tight_edges_are_exact():
    """The mesh error is measured on every face, not only on those whose edges carry more
    than the deflection: a face BRepMesh misses by over 3x gets the exact (u, v) grid."""
    part, caster = _trj8()
    x, y = np.array(TIGHT_FACE_POINTS).T
    z, face, how = sample_points(part, x, y, deflection=0.005)
    zr, fr = caster(x, y)
    assert face.tolist() == fr.tolist() == [361, 361, 352, 316, 352]
    assert (how == 1).all(), how
    np.testing.assert_allclose(z, zr, rtol=0, atol=1e-6)


@pytest.mark.slow
def test_trj8_converted_plane_band_seen_from_the_side():
    """Seen along -y, trj8's planes 135 and 52 (edges 0.17 and 0.11 mm) hold points 0.14 and
    0.11 mm outside their loops, as OCC's ray cast has them: OCC classifies on the plane,
    whose uv resolution is the tolerance itself, where the converted B-spline's pole bound
    gave 0.119 and 0.079, and the faces behind answered, 6.8e-3 and 4e-3 mm lower."""
    from cad_io.raycast import RayCaster, read_shape

    part, _ = _trj8()
    x, y = np.array([161.2439, 151.7439]), np.array([32.0, -21.5])
    z, face, how = sample_points(part, x, y, axis="-y")
    zr, fr = RayCaster(read_shape(TRJ8), axis="-y")(x, y)
    assert fr.tolist() == [135, 52] and (how == 1).all()
    np.testing.assert_allclose(z, zr, rtol=0, atol=1e-6)
    assert face.tolist() == [135, 52]


def test_in_tolerance_kernel():
    """The band test alone on the unit square's loop, 10 mm per unit of u along its edge
    v = 0 in space: near a loop edge in uv and near an edge curve in space, inside the
    face's uv bounds; a face without a tolerance (0) has no band."""
    from cad_io._sample_trim import _trim_bands, _with_band
    from cad_io._trim_kernels import in_tolerance

    loop = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    trim = _trim_bands({0: [loop]}, np.array([[-1.0, 2.0, -1.0, 2.0]]), 1, reach_uv={0: 0.02})
    seg = np.array([[0.0, 0.0, 0.0, 10.0, 0.0, 0.0]])  # the edge v = 0 in space
    tol = np.array([[0.2, 0.02, -1.0, 2.0, -1.0, 2.0, -1.0, 12.0]])  # one x band over -1..11

    def band(u, v, x, y, z, t=tol):
        arrays = _with_band(trim, (t, np.array([[0, 1]]), seg, np.array([0, 1]), np.array([0])))
        return in_tolerance(u, v, x, y, z, 0, *arrays)

    assert band(0.5, -0.01, 5.0, -0.1, 0.0)
    assert not band(0.5, -0.03, 5.0, -0.3, 0.0)  # too far in uv
    assert not band(0.5, -0.01, 5.0, -0.1, 0.25)  # too far in space
    bounded = tol.copy()
    bounded[0, 4] = 0.0
    assert not band(0.5, -0.01, 5.0, -0.1, 0.0, bounded)  # beyond the uv bounds
    none = tol.copy()
    none[0, 0] = 0.0
    assert not band(0.5, -0.01, 5.0, -0.1, 0.0, none)


def test_trim_follows_the_files_tolerance_on_curved_edges(tmp_path):
    """A round boss (r 5, 12.7 mm high) on a plate, edges at 1e-7 mm as cadquery writes them.
    The trim loops are polygons within 1e-4 mm of the circle, and a slack of 5e-4 mm let the
    boss's top claim 383 of 400 points 1e-7 to 4e-4 mm outside the circle, 12.7 mm above the
    plate that OCC's ray cast sees there (a NIST part's wall corners showed it). The loops now
    carry each chord's bulge and the slack is the file's tolerance: every point farther than
    twice the tolerance from the circle, inside or outside, has OCC's height."""
    import cadquery as cq

    from cad_io.raycast import RayCaster

    path = tmp_path / "boss.step"
    cq.exporters.export(cq.Workplane("XY").box(30, 30, 2, centered=(True, True, False))
                        .faces(">Z").workplane().circle(5).extrude(12.7), str(path))
    part = read_step(path)
    assert max(f.tolerance for f in part.faces) <= 1e-7
    rng = np.random.default_rng(0)
    off = np.repeat([2e-7, 4e-7, 1e-6, 1e-5, 5e-5, 1e-4, 2e-4, 4e-4], 50)
    a = rng.uniform(0, 2 * np.pi, off.size)
    r = np.r_[5 + off, 5 - off]
    a = np.r_[a, a]
    x, y = r * np.cos(a), r * np.sin(a)
    z = sample_points(part, x, y)[0]
    zr = RayCaster(part.shape)(x, y)[0]
    assert np.all(zr[: off.size] == pytest.approx(2.0)) and np.all(zr[off.size:] == pytest.approx(14.7))
    np.testing.assert_allclose(z, zr, rtol=0, atol=1e-9)
