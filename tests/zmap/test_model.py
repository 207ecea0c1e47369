"""PrecisionModel: CZ lookup, base fallback, exact save/load."""

from __future__ import annotations

import math

import numpy as np
import pytest

from zmap import ZMap
from zmap.errors import OutOfDomainError, ZMapFileError
from zmap.interpolate import bezier
from zmap.model import PrecisionModel


def _wall(x, y):
    return np.where(x < 1.02 + 0.1 * y, 0.0, 3.0)


def _model():
    base = ZMap.from_function(_wall, (0, 0, 4, 3), 0.5)
    c1 = ZMap.from_function(lambda u, v: _wall(*_rot(u, v)), (-0.3, 0, 0.3, 3), 0.01, 0.03)
    c1 = ZMap(c1.x0, c1.y0, c1.dx, c1.dy, _grid_heights(0.3, 0.0), angle=0.0, origin=(1.02, 0.0))
    return base, PrecisionModel(base, [c1], meta={"tol": 0.01})


def _rot(u, v):
    return u, v


def _grid_heights(half, _):
    xs = -half + 0.01 * np.arange(61)
    ys = 0.03 * np.arange(101)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    return _wall(X + 1.02, Y)


def test_sources_and_base_fallback():
    base, m = _model()
    x = np.array([1.0, 3.5, 100.0])
    y = np.array([1.0, 1.0, 1.0])
    assert m.source(x, y).tolist() == [2, 1, 0]
    h = m.height(x, y)
    assert h[1] == bezier(base, 3.5, 1.0)
    assert np.isnan(h[2])
    with pytest.raises(OutOfDomainError, match="point 2"):
        m.height(x, y, strict=True)


def test_nbytes_breakdown():
    base, m = _model()
    nb = m.nbytes
    assert nb["base"] == base.z.nbytes
    assert nb["total"] == nb["base"] + nb["cz"] + nb["ez"]
    assert nb["cz"] >= m.cz[0].z.nbytes and nb["ez"] == 0


def test_save_load_round_trip(tmp_path):
    rng = np.random.default_rng(3)
    base = ZMap(-1.5, 2.25, 0.5, 0.4, rng.normal(size=(9, 7)), layers={"face": np.ones((9, 7), np.int32)})
    base.z[2, 3] = np.nan
    cz = [ZMap(rng.uniform(-1, 1), rng.uniform(-1, 1), 0.03, 0.01, rng.normal(size=(5, 6)),
               angle=float(rng.uniform(-math.pi, math.pi)), origin=(float(rng.normal()), float(rng.normal())))
          for _ in range(3)]
    m = PrecisionModel(base, cz, meta={"tol": 0.01, "source": "x"})
    p = m.save(tmp_path / "a.zpm")
    m2 = PrecisionModel.load(p)
    assert np.array_equal(m2.base.z, base.z, equal_nan=True)
    assert np.array_equal(m2.base.layers["face"], base.layers["face"])
    for a, b in zip(m2.cz, cz):
        assert np.array_equal(a.z, b.z) and (a.x0, a.y0, a.dx, a.dy, a.angle, a.origin) == (
            b.x0, b.y0, b.dx, b.dy, b.angle, b.origin)
    assert m2.meta == m.meta
    xs = rng.uniform(-2, 3, 2000)
    ys = rng.uniform(1, 6, 2000)
    assert np.array_equal(m.height(xs, ys), m2.height(xs, ys), equal_nan=True)


def test_load_foreign_file(tmp_path):
    p = ZMap(0, 0, 1, 1, np.zeros((2, 2))).save(tmp_path / "a.zmap.npz")
    with pytest.raises(ZMapFileError, match="format"):
        PrecisionModel.load(p)
