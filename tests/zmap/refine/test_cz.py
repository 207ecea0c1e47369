"""CZ-maps on an analytic wall hold the tolerance inside their domains."""

from __future__ import annotations

import math

import numpy as np
import pytest

from zmap import ZMap
from zmap.model import PrecisionModel
from zmap.refine.cz import build_cz, cz_intervals, cz_layout, split_runs

TOL = 0.01


def _wall(x, y):
    """Step of 5 mm along the line x = 2.013 + 0.2 y (about 11 degrees off the y-axis)."""
    return np.where(x < 2.013 + 0.2 * y, 0.0, 5.0)


def test_intervals_and_runs():
    ddx, ddy = cz_intervals(TOL, math.radians(20))
    assert ddy == TOL and ddx == pytest.approx(TOL / math.tan(math.radians(20)))
    sq = np.array([[0, 0], [1, 0], [1, 1], [0, 1.0]])
    assert split_runs(sq, math.radians(20), 0.5) == [(0, 1), (1, 2), (2, 3)]
    with pytest.raises(ValueError, match="theta_x"):
        cz_intervals(TOL, math.radians(60))


def test_tol_not_below_grid():
    base = ZMap.from_function(_wall, (0, 0, 4, 3), 0.5)
    with pytest.raises(ValueError, match="grid interval"):
        build_cz(base, _wall, tol=0.5, curves=[np.array([[2.0, 0.0], [2.6, 3.0]])])


def test_wall_held_inside_domains():
    base = ZMap.from_function(_wall, (0, 0, 4, 3), 0.5)
    curve = np.array([[2.013 + 0.2 * y, y] for y in np.linspace(0, 3, 7)])
    cz = build_cz(base, _wall, tol=TOL, curves=[curve])
    assert len(cz) == 1  # one straight run: one domain
    c = cz[0]
    assert c.dy == TOL and c.dx == pytest.approx(TOL / math.tan(math.radians(20)))
    m = PrecisionModel(base, cz)
    rng = np.random.default_rng(0)
    x = rng.uniform(0, 4, 200_000)
    y = rng.uniform(0, 3, 200_000)
    h = m.height(x, y)
    inside = m.source(x, y) == 2
    assert inside.sum() > 10_000
    # 3D distance from (x, y, h) to the step surface: floor, top or the wall plane
    xw = 2.013 + 0.2 * y
    dwall = np.abs(x - xw) / math.hypot(1.0, 0.2)
    on_wall_z = (h >= 0) & (h <= 5)
    d = np.where(x < xw, np.abs(h), np.abs(h - 5.0))
    d = np.minimum(d, np.where(on_wall_z, dwall, np.inf))
    assert d[inside].max() <= TOL
    base_only = PrecisionModel(base)
    hb = base_only.height(x, y)
    db = np.minimum(np.where(x < xw, np.abs(hb), np.abs(hb - 5.0)), np.where((hb >= 0) & (hb <= 5), dwall, np.inf))
    assert db.max() > 0.1


def test_layout_is_what_build_samples():
    base = ZMap.from_function(_wall, (0, 0, 4, 3), 0.5)
    curves = [np.array([[2.013 + 0.2 * y, y] for y in np.linspace(0, 3, 7)]),
              np.array([[0.5, 0.5], [1.5, 0.6], [1.6, 2.5]])]
    calls = []

    def counting(x, y):
        calls.append(np.size(x))
        return _wall(x, y)

    cz = build_cz(base, counting, tol=TOL, curves=curves)
    lay = cz_layout(base, tol=TOL, curves=curves)
    assert lay.tolist() == [list(c.shape) for c in cz] and int(lay.prod(axis=1).sum()) == sum(calls)
    with pytest.raises(ValueError, match="grid interval"):
        cz_layout(base, tol=0.5, curves=curves)
