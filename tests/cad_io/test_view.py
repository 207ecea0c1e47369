"""View axes: right-handed signed permutations; parts transform exactly."""

from __future__ import annotations

import numpy as np
import pytest

from cad_io.part import Face, FaceMesh, NurbsSurface, Part
from cad_io.view import AXES, from_view, to_view, transform_part, view_matrix


@pytest.mark.parametrize("axis", AXES)
def test_view_matrix_is_a_rotation_with_the_axis_as_z(axis):
    R = view_matrix(axis)
    assert np.allclose(R @ R.T, np.eye(3))
    assert np.isclose(np.linalg.det(R), 1.0)
    world = np.zeros(3)
    world["xyz".index(axis[1])] = 1.0 if axis[0] == "+" else -1.0
    assert np.allclose(R @ world, [0, 0, 1])
    p = np.random.default_rng(0).normal(size=(5, 3))
    assert np.allclose(from_view(to_view(p, axis), axis), p)


def test_bad_axis():
    with pytest.raises(ValueError, match="axis='z' is not one of"):
        view_matrix("z")


@pytest.mark.parametrize("axis", AXES)
def test_transform_part(axis):
    poles = np.arange(2 * 2 * 3, dtype=float).reshape(2, 2, 3)
    s = NurbsSurface(1, 1, np.array([0.0, 0, 1, 1]), np.array([0.0, 0, 1, 1]), poles, np.ones((2, 2)))
    nodes = poles.reshape(-1, 3)
    mesh = FaceMesh(nodes, np.array([[0, 1, 2]], dtype=np.int32), np.zeros((4, 2)), 0.1)
    lo, hi = nodes.min(0), nodes.max(0)
    part = Part([Face(0, "bspline", s, bbox=(*lo, *hi), mesh=mesh)], source="t")
    v = transform_part(part, axis)
    R = view_matrix(axis)
    assert np.allclose(v.faces[0].surface.poles, poles @ R.T)
    assert np.allclose(v.faces[0].mesh.nodes, nodes @ R.T)
    vn = nodes @ R.T
    assert np.allclose(v.faces[0].bbox, (*vn.min(0), *vn.max(0)))
    assert part.faces[0].surface.poles is poles  # the input is untouched


def test_view_part_meshes_and_measures_in_the_view_frame():
    from pathlib import Path

    from cad_io.distance import occ_distance
    from cad_io.sampler import TRIM_SLACK_MM, sample, sample_points
    from cad_io.step import read_step
    from cad_io.view import view_part

    part = read_step(Path(__file__).resolve().parents[2] / "data" / "boss.step")
    zm = sample(part, 2.0, axis="+y")
    vpart = view_part(part, "+y")
    assert view_part(part, "+z") is part
    X, Y = zm.grid_points()
    z = sample_points(vpart, X, Y, deflection=0.01)[0]
    both = np.isfinite(z) & (zm.layers["method"] == 1)  # exact (Newton) heights on both sides
    assert both.sum() > 0.5 * zm.z.size
    # at a trim boundary two meshes may pick different faces within the trim slack (5e-4 mm)
    np.testing.assert_allclose(z[both], zm.z[both], atol=TRIM_SLACK_MM)
    assert np.mean(np.abs(z[both] - zm.z[both]) < 1e-9) > 0.95
    pts = np.c_[X[both], Y[both], z[both]][:20]
    assert np.max(occ_distance(vpart.shape, pts)) < 1e-6  # the OCP shape turned with the NURBS
