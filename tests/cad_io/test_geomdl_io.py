"""cad_io.from_geomdl: faces, shared boundary edges, dihedral angles, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from cad_io.geomdl_io import from_geomdl
from cad_io.nurbs import evaluate

geomdl = pytest.importorskip("geomdl")
from geomdl import NURBS, BSpline


def _bilinear(corners):
    """A degree-1 BSpline surface through 4 corners (a, b) in {0,1}^2 (v fastest)."""
    s = BSpline.Surface()
    s.degree_u, s.degree_v = 1, 1
    s.ctrlpts_size_u, s.ctrlpts_size_v = 2, 2
    s.ctrlpts = [list(map(float, c)) for c in corners]
    s.knotvector_u = s.knotvector_v = [0, 0, 1, 1]
    return s


def _quarter_cylinder(r=5.0, h=3.0):
    """Exact rational quarter cylinder x^2 + y^2 = r^2, 0 <= z <= h (u around, v up)."""
    s = NURBS.Surface()
    s.degree_u, s.degree_v = 2, 1
    s.ctrlpts_size_u, s.ctrlpts_size_v = 3, 2
    w = np.sqrt(0.5)
    pts = [[r, 0, 0], [r, 0, h], [r, r, 0], [r, r, h], [0, r, 0], [0, r, h]]
    s.ctrlpts = pts
    s.weights = [1, 1, w, w, 1, 1]
    s.knotvector_u = [0, 0, 0, 1, 1, 1]
    s.knotvector_v = [0, 0, 1, 1]
    return s


def test_rational_surface_exact():
    part = from_geomdl(_quarter_cylinder())
    f = part.faces[0]
    assert f.kind == "bspline" and f.loops == [] and not f.reversed and f.surface.rational
    rng = np.random.default_rng(0)
    u, v = rng.uniform(0, 1, 100), rng.uniform(0, 1, 100)
    p = evaluate(f.surface, u, v)[:, 0]
    np.testing.assert_allclose(np.hypot(p[:, 0], p[:, 1]), 5.0, atol=1e-12)
    np.testing.assert_allclose(f.bbox, (0, 0, 0, 5, 5, 3), atol=1e-9)
    assert part.shape is None and part.source == "geomdl"
    assert len(part.edges) == 4 and all(e.is_boundary for e in part.edges)


def test_matches_geomdl_evaluation():
    s = _quarter_cylinder()
    f = from_geomdl([s]).faces[0]
    for u, v in [(0.1, 0.2), (0.5, 0.9), (1.0, 0.0)]:
        np.testing.assert_allclose(evaluate(f.surface, u, v)[0], s.evaluate_single((u, v)),
                                   atol=1e-12)


def test_shared_boundaries_become_edges_with_dihedral():
    # two faces of a unit cube meeting at a right angle along x = 1, z = 0, and a flat
    # continuation of the bottom face (dihedral 0), joined with reversed direction
    bottom = _bilinear([(0, 0, 0), (0, 1, 0), (1, 0, 0), (1, 1, 0)])
    side = _bilinear([(1, 0, 0), (1, 0, 1), (1, 1, 0), (1, 1, 1)])
    flat = _bilinear([(0, 1, 0), (0, 0, 0), (-1, 1, 0), (-1, 0, 0)])
    part = from_geomdl([bottom, side, flat], source="cube bits")
    shared = {e.faces: e for e in part.edges if not e.is_boundary}
    assert set(shared) == {(0, 1), (0, 2)}
    assert abs(shared[(0, 1)].dihedral - np.pi / 2) < 1e-12
    # the flat piece runs the other way along the shared edge, its normal is +z too
    assert abs(shared[(0, 2)].dihedral) < 1e-12
    assert len(part.edges) == 12 - 2
    assert sum(e.is_boundary for e in part.edges) == 8
    flipped = _bilinear([(0, 0, 0), (0, 1, 0), (-1, 0, 0), (-1, 1, 0)])  # normal -z
    part = from_geomdl([bottom, flipped])  # faces back to back: pi
    assert abs(part.edges[[e.faces for e in part.edges].index((0, 1))].dihedral
               - np.pi) < 1e-12


def test_collapsed_boundary_is_not_an_edge():
    # a triangle-like patch whose u = 0 boundary collapses to a point
    s = _bilinear([(0, 0, 0), (0, 0, 0), (1, 0, 0), (1, 1, 0)])
    part = from_geomdl(s)
    assert len(part.edges) == 3


def test_bad_input():
    with pytest.raises(TypeError, match="geomdl NURBS or BSpline Surface, got int"):
        from_geomdl([_bilinear([(0, 0, 0), (0, 1, 0), (1, 0, 0), (1, 1, 0)]), 3])
    with pytest.raises(ValueError, match="at least one surface"):
        from_geomdl([])
