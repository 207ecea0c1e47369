"""distance_to_part against OCC's BRepExtrema_DistShapeShape."""

from __future__ import annotations

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
def test_real_part_matches_occ(shared_data):
    part = read_step(shared_data / "step" / "featuretype.STEP")
    pts = _near_surface(part, 100, 2)
    d = distance_to_part(part, pts, deflection=0.005)
    ref = _occ_distance(part.shape, pts)
    assert np.max(np.abs(d - ref)) <= 0.005


def test_on_surface_is_zero_and_nan_rows():
    part = read_step(DATA / "pocket.step")
    d = distance_to_part(part, [[0.0, 0.0, 15.0], [0.0, 0.0, 16.0], [np.nan, 0.0, 0.0]])
    assert d[0] == pytest.approx(0.0, abs=1e-8)
    assert d[1] == pytest.approx(1.0, abs=1e-8)
    assert np.isnan(d[2])
    with pytest.raises(ValueError, match="shape"):
        distance_to_part(part, np.zeros((3, 2)))


def test_dense_face_does_not_crowd_out_the_nearest_one():
    # Beside the pocket's corner torus a floor-fillet cylinder is meshed far more densely;
    # its samples used to fill all the nearest neighbours and the distance came out 0.044
    # where OCC gives 0.00038.
    part = read_step(DATA / "pocket.step")
    pts = np.array([[22.0441, 18.498, 15.4013], [-28.8087, 12.0374, 15.6071]])
    d = distance_to_part(part, pts, deflection=0.002)
    np.testing.assert_allclose(d, _occ_distance(part.shape, pts), atol=1e-6)
