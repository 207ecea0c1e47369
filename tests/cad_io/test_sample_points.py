"""sample_points: the grid sampler's heights at scattered points."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cad_io.sampler import height_function, sample, sample_points
from cad_io.step import read_step

DATA = Path(__file__).resolve().parents[2] / "data"


@pytest.fixture(scope="module")
def boss():
    return read_step(DATA / "boss.step")


def test_equals_grid_sampler_at_grid_points(boss):
    zm = sample(boss, 1.0)
    X, Y = zm.grid_points()
    z, face, how = sample_points(boss, X, Y, deflection=zm.meta["deflection"])
    assert np.array_equal(np.isnan(z), np.isnan(zm.z))
    assert np.array_equal(z[np.isfinite(z)], zm.z[np.isfinite(zm.z)])
    assert np.array_equal(how, zm.layers["method"])
    assert np.array_equal(face, zm.layers["face"])


def test_exact_tops_and_nan(boss):
    z, _, how = sample_points(boss, [-15.0, 22.0, 30.0, 500.0, np.nan], [5.0, -12.0, 25.0, 0.0, 0.0])
    assert np.allclose(z[:3], [22.0, 16.0, 10.0], atol=1e-9)
    assert np.isnan(z[3:]).all() and (how[3:] == 0).all()


def test_height_function_and_bad_method(boss):
    h = height_function(boss)
    assert h(np.array([[-15.0]]), np.array([[5.0]])).shape == (1, 1)
    with pytest.raises(ValueError, match="method"):
        sample_points(boss, 0.0, 0.0, method="newton")


def test_points_on_a_curved_wall_top_never_fall_through_to_a_lower_face():
    # Pocket corner: wall arc of radius 8 about (22, 12), top at 30, fillet edge at 18.
    # Within the trim polygons' 1e-4 mm chord error of the arc, a point used to miss both the
    # top face and the fillet, and the block's bottom face (z = 0) answered.
    part = read_step(DATA / "pocket.step")
    th = np.linspace(0.01, np.pi / 2 - 0.01, 2000)
    for r in (8.0, 8.0 - 1e-6, 8.0 - 1e-4, 8.0 + 1e-6):
        z, _, _ = sample_points(part, 22 + r * np.cos(th), 12 + r * np.sin(th))
        assert np.all(z > 17.9), (r, np.unique(np.round(z, 4)))


def test_points_inside_a_curved_wall_get_the_fillet_not_the_top():
    # 1 and 3 um inside the pocket's corner wall the surface is the floor fillet (R 3 up to
    # z = 18): points there pair with the top face's boundary triangles (mesh margin) but its
    # trim loops reject them, and the fillet answers.
    part = read_step(DATA / "pocket.step")
    th = np.linspace(0.01, np.pi / 2 - 0.01, 2000)
    for d in (1e-3, 3e-3):
        z, _, _ = sample_points(part, 22 + (8 - d) * np.cos(th), 12 + (8 - d) * np.sin(th), deflection=0.005)
        fillet = 15 + 3 - np.sqrt(9 - (3 - d) ** 2)
        assert np.sum(np.abs(z - fillet) < 1e-6) >= 0.99 * th.size
        assert np.all((z > 17.5) & (z <= 18.0 + 1e-9))


def test_chunks_give_the_same_answer(monkeypatch):
    # sample_points solves the points POINTS_CHUNK at a time (bounded working memory)
    import cad_io._sample_points as SP
    import cad_io.sampler as S

    part = read_step(Path(__file__).resolve().parents[2] / "data" / "boss.step")
    rng = np.random.default_rng(3)
    x, y = rng.uniform(-45, 45, 300), rng.uniform(-35, 35, 300)
    x[5] = np.nan
    whole = S.sample_points(part, x, y)
    monkeypatch.setattr(SP, "POINTS_CHUNK", 7)
    chunked = S.sample_points(part, x, y)
    for a, b in zip(whole, chunked):
        np.testing.assert_array_equal(a, b)


def _two_faces(tmp_path, tolerance: float):
    """A 10 x 10 top face at z = 5 over a 20 x 10 floor at z = 3, the top face's trim loop
    pulled 5e-3 mm inside its true boundary (as a file's pcurves may lie, within their edge
    tolerance, off the edge they share with the next face) and its edge tolerance set."""
    cq = pytest.importorskip("cadquery")
    top = cq.Face.makeFromWires(cq.Wire.makePolygon([(0, 0, 5), (10, 0, 5), (10, 10, 5), (0, 10, 5)], close=True))
    floor = cq.Face.makeFromWires(cq.Wire.makePolygon([(0, 0, 3), (20, 0, 3), (20, 10, 3), (0, 10, 3)], close=True))
    path = tmp_path / "two_faces.step"
    cq.exporters.export(cq.Compound.makeCompound([top, floor]), str(path))
    part = read_step(path)
    k = int(np.argmax([f.bbox[5] for f in part.faces]))
    face = part.faces[k]
    (loop,) = face.loops
    c = loop.mean(axis=0)
    face.loops = [c + (loop - c) * (5.0 - 5e-3) / 5.0]  # uv of a plane are mm here
    face.tolerance = tolerance
    return part


@pytest.mark.parametrize("tolerance,expect", [(0.0, 3.0), (7.7e-3, 5.0)])
def test_edge_tolerance_of_the_file_is_honoured(tmp_path, tolerance, expect):
    """Points between a face's trim curve and its true edge (within the edge's tolerance in the
    file, 7.7e-3 mm on a soap-box moulding, above the 5e-4 mm slack) belong to the face: with
    the tolerance honoured they get the top (5), not the floor 2 mm below (the bug: 3)."""
    part = _two_faces(tmp_path, tolerance)
    x = np.array([9.997, 9.999, 10.0, 0.003, 5.0])
    y = np.array([5.0, 5.0, 5.0, 5.0, 9.998])
    z, _, how = sample_points(part, x, y, deflection=0.05)
    np.testing.assert_allclose(z, expect, atol=1e-9)
    assert (how == 1).all()
    # well inside the face and beyond its tolerance the answers do not depend on it
    z2, _, _ = sample_points(part, [5.0, 10.02], [5.0, 5.0], deflection=0.05)
    np.testing.assert_allclose(z2, [5.0, 3.0], atol=1e-9)
