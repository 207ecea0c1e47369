"""Feature curves: eps_r, steep edges, VW tracing, SE selection, edges crossed by polylines."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from zmap import ZMap
from zmap.features import (
    default_eps_r,
    edges_crossing,
    sharp_edge_curves,
    steep_edges,
    vertical_wall_curves,
)

DATA = Path(__file__).resolve().parents[2] / "data"


def ramp_distance(H: float, h: float, n: int = 200001) -> float:
    """Largest 3D distance from a linear ramp over one interval h to a step of height H
    in its middle (exact surface: floor, wall, top), by dense evaluation."""
    d = np.linspace(-h / 2, h / 2, n)
    z = H * (d + h / 2) / h
    to_floor = np.where(d < 0, np.abs(z), np.hypot(d, z))
    to_top = np.where(d > 0, np.abs(z - H), np.hypot(d, z - H))
    to_wall = np.hypot(d, z - np.clip(z, 0, H))
    return float(np.minimum(np.minimum(to_floor, to_top), to_wall).max())


@pytest.mark.parametrize("tol,h", [(0.01, 0.5), (0.02, 0.8), (0.05, 1.0)])
def test_default_eps_r_is_the_slope_where_a_step_costs_tol(tol, h):
    eps = default_eps_r(tol, h, 0.5 * h)  # the larger interval sets it
    assert eps == pytest.approx(2 * tol / (h - 2 * tol))
    # a step just at the threshold is held by the base ramp within tol, exactly at its limit
    assert ramp_distance(eps * h, h) == pytest.approx(tol, rel=1e-4)
    assert ramp_distance(1.2 * eps * h, h) > tol


def test_default_eps_r_bad_input_and_coarse_tolerance():
    assert default_eps_r(0.3, 0.5, 0.5) == math.inf
    with pytest.raises(ValueError, match="tol"):
        default_eps_r(0.0, 0.5, 0.5)
    with pytest.raises(ValueError, match="dx and dy"):
        default_eps_r(0.01, -1.0, 0.5)


def test_steep_edges_threshold_inclusive_and_nan_aware():
    z = np.array([[0.0, 0.0, np.nan], [1.0, 0.2, 5.0], [1.0, 0.2, np.nan]])
    zm = ZMap(0.0, 0.0, 0.5, 0.5, z)
    sx, sy = steep_edges(zm, 2.0)
    assert sx.shape == (2, 3) and sy.shape == (3, 2)
    # |1 - 0| / 0.5 = 2 (inclusive); edges with a NaN end never steep
    assert sx.tolist() == [[True, False, False], [False, False, False]]
    assert sy.tolist() == [[False, False], [False, True], [False, False]]
    with pytest.raises(ValueError, match="eps_r"):
        steep_edges(zm, -1.0)


def test_vw_curve_of_a_straight_wall():
    zm = ZMap.from_function(lambda x, y: np.where(x > 1.3, 4.0, 0.0), (0, 0, 3, 2), 0.5)
    curves = vertical_wall_curves(zm, 1.0)
    assert len(curves) == 1
    c = curves[0]
    assert c.shape == (5, 2)
    assert np.allclose(c[:, 0], 1.25) and sorted(c[:, 1]) == [0.0, 0.5, 1.0, 1.5, 2.0]


@pytest.mark.parametrize("angle", [0.0, 0.4])
def test_vw_curve_of_a_circular_boss_is_one_closed_loop_within_half_an_interval(angle):
    R, cx, cy = 2.3, 5.1, 4.9
    zm0 = ZMap.from_function(lambda x, y: np.where(np.hypot(x - cx, y - cy) <= R, 5.0, 0.0), (0, 0, 10, 10), 0.25)
    # the same map in a rotated frame: curves come back in world xy
    zm = ZMap(zm0.x0, zm0.y0, zm0.dx, zm0.dy, zm0.z, angle=angle, origin=(1.0, -2.0))
    wcx, wcy = zm.local_to_world(cx, cy)
    curves = vertical_wall_curves(zm, 1.0)
    assert len(curves) == 1
    c = curves[0]
    assert np.array_equal(c[0], c[-1])  # closed
    r = np.hypot(c[:, 0] - wcx, c[:, 1] - wcy)
    assert np.all(np.abs(r - R) <= 0.5 * 0.25 + 1e-12)
    steps = np.hypot(*np.diff(c, axis=0).T)
    assert steps.max() <= math.hypot(0.125, 0.125) * 2 + 1e-12  # neighbours in one cell


def test_sharp_edge_curves_selection():
    E = SimpleNamespace
    pts = [np.array([[0.0, 0, 1], [1, 0, 1]]), np.array([[0.0, 1, 0], [2, 1, 0]]), np.array([[5.0, 5, 0], [6, 6, 1]]),
           np.array([[7.0, 7, 7]])]
    edges = [E(points=pts[0], dihedral=math.radians(90), is_boundary=False),
             E(points=pts[1], dihedral=math.radians(10), is_boundary=False),
             E(points=pts[2], dihedral=np.nan, is_boundary=True),
             E(points=pts[3], dihedral=math.radians(90), is_boundary=False)]
    got = sharp_edge_curves(edges)
    assert [g.tolist() for g in got] == [pts[0][:, :2].tolist(), pts[2][:, :2].tolist()]
    assert len(sharp_edge_curves(edges, boundary=False)) == 1
    assert len(sharp_edge_curves(edges, min_dihedral=math.radians(5))) == 3
    # a view along -y: view x = world x, view y = world z
    rot = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])
    assert sharp_edge_curves(edges[:1], axis_matrix=rot)[0].tolist() == [[0.0, 1.0], [1.0, 1.0]]
    with pytest.raises(ValueError, match=r"edge 0: points must have shape \(n, 3\)"):
        sharp_edge_curves([E(points=np.zeros((3, 2)), dihedral=1.0, is_boundary=False)])


def test_sharp_edge_curves_of_the_boss_lie_on_its_outlines():
    cad_io = pytest.importorskip("cad_io")
    part = cad_io.read_step(DATA / "boss.step")
    curves = sharp_edge_curves(part.edges)
    assert len(curves) > 10
    xy = np.concatenate(curves)
    on_plate = (np.abs(np.abs(xy[:, 0]) - 40) < 1e-6) | (np.abs(np.abs(xy[:, 1]) - 30) < 1e-6)
    on_rect = (((np.abs(xy[:, 0] + 30) < 1e-6) | (np.abs(xy[:, 0]) < 1e-6)) & (xy[:, 1] > -5 - 1e-6) & (xy[:, 1] < 15 + 1e-6)) | (
        ((np.abs(xy[:, 1] + 5) < 1e-6) | (np.abs(xy[:, 1] - 15) < 1e-6)) & (xy[:, 0] > -30 - 1e-6) & (xy[:, 0] < 1e-6))
    on_circle = np.abs(np.hypot(xy[:, 0] - 22, xy[:, 1] + 12) - 8) < 1e-3
    assert np.all(on_plate | on_rect | on_circle)
    assert on_circle.any() and on_rect.any()


def _brute_crossings(zm, a, b):
    """Grid edges met by segment a-b, by exact segment-segment intersection (non-parallel)."""
    nx, ny = zm.shape
    cx = np.zeros((nx - 1, ny), bool)
    cy = np.zeros((nx, ny - 1), bool)

    def hit(p, q, r, s):
        d = (q[0] - p[0]) * (s[1] - r[1]) - (q[1] - p[1]) * (s[0] - r[0])
        if d == 0:
            return False
        t = ((r[0] - p[0]) * (s[1] - r[1]) - (r[1] - p[1]) * (s[0] - r[0])) / d
        u = ((r[0] - p[0]) * (q[1] - p[1]) - (r[1] - p[1]) * (q[0] - p[0])) / d
        return 0 <= t <= 1 and 0 <= u <= 1

    for i in range(nx - 1):
        for j in range(ny):
            cx[i, j] = hit(a, b, (zm.x[i], zm.y[j]), (zm.x[i + 1], zm.y[j]))
    for i in range(nx):
        for j in range(ny - 1):
            cy[i, j] = hit(a, b, (zm.x[i], zm.y[j]), (zm.x[i], zm.y[j + 1]))
    return cx, cy


def _distance_to_nodes(zm, a, b) -> float:
    """Smallest distance from a grid node to segment a-b."""
    gx, gy = np.meshgrid(zm.x, zm.y, indexing="ij")
    p = np.stack([gx.ravel(), gy.ravel()], axis=1)
    a, b = np.asarray(a), np.asarray(b)
    d = b - a
    t = np.clip(((p - a) @ d) / max(float(d @ d), 1e-300), 0.0, 1.0)
    return float(np.min(np.hypot(*(a + t[:, None] * d - p).T)))


@settings(max_examples=40, deadline=None)
@given(st.floats(-1, 4), st.floats(-1, 3), st.floats(-1, 4), st.floats(-1, 3))
def test_edges_crossing_matches_brute_force(ax, ay, bx, by):
    # offsets move the segment off grid points, where "which edge" is a convention; a segment
    # that still passes within 1e-6 of a node (ax == bx == 0 runs along a grid line) is skipped
    a, b = (ax + 1e-7, ay + 3e-7), (bx - 2e-7, by + 1e-7)
    zm = ZMap(0.0, 0.0, 0.5, 0.5, np.zeros((7, 5)))
    assume(_distance_to_nodes(zm, a, b) > 1e-6)
    cx, cy = edges_crossing(zm, [np.array([a, b])])
    ex, ey = _brute_crossings(zm, a, b)
    assert np.array_equal(cx, ex) and np.array_equal(cy, ey)


def test_edges_crossing_polyline_and_bad_input():
    zm = ZMap(0.0, 0.0, 1.0, 1.0, np.zeros((4, 4)))
    cx, cy = edges_crossing(zm, [np.array([[0.5, -1.0], [0.5, 1.5], [2.5, 1.5]]), np.zeros((1, 2))])
    assert np.flatnonzero(cx[0]).tolist() == [0, 1] and not cx[1:].any()
    assert np.argwhere(cy).tolist() == [[1, 1], [2, 1]]
    with pytest.raises(ValueError, match=r"curve 0 must have shape \(n, 2\)"):
        edges_crossing(zm, [np.zeros((3, 3))])
