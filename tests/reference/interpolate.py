"""Slow, obvious reference implementations to check the numba kernels against.

Plain Python per point, written straight from paper 004 Eq. 4-7: the 12 grid points of
Fig. 4, dummy points by linear extrapolation at the domain edge, the circular tangent by
fitting the circle through three points with a general 3x3 solve.
"""

from __future__ import annotations

import math

import numpy as np

from zmap.grid import ZMap

__all__ = ["bezier_reference", "bilinear_reference"]


def _cell(zm: ZMap, x: float, y: float, slack: float = 1e-9):
    """Cell indices and (u, v) of a point, or None outside the domain (slack for rounding)."""
    fi, fj = (float(a) for a in zm.index_of(x, y))
    if not (-slack <= fi <= zm.nx - 1 + slack and -slack <= fj <= zm.ny - 1 + slack):
        return None
    fi = min(max(fi, 0.0), zm.nx - 1.0)
    fj = min(max(fj, 0.0), zm.ny - 1.0)
    i, j = min(int(fi), zm.nx - 2), min(int(fj), zm.ny - 2)
    return i, j, fi - i, fj - j


def _circle_slope(p1: tuple[float, float], p2: tuple[float, float], p3: tuple[float, float]) -> float:
    """Slope at p2 of the circle x^2 + z^2 + D x + E z + F = 0 through p1, p2, p3."""
    a = np.array([[p[0], p[1], 1.0] for p in (p1, p2, p3)])
    b = np.array([-(p[0] ** 2 + p[1] ** 2) for p in (p1, p2, p3)])
    if abs(np.linalg.det(a)) < 1e-12 * max(1.0, np.abs(a).max() ** 2):
        return (p3[1] - p1[1]) / (p3[0] - p1[0])  # collinear: the line's slope
    d, e, _ = np.linalg.solve(a, b)
    cx, cz = -d / 2.0, -e / 2.0
    return -(p2[0] - cx) / (p2[1] - cz)


def _line_heights(values: list[float]) -> list[float]:
    """Replace missing end points (None) of a 4-point line by linear extrapolation."""
    v = list(values)
    if v[0] is None:
        v[0] = 2.0 * v[1] - v[2]
    if v[3] is None:
        v[3] = 2.0 * v[2] - v[1]
    return v


def _bezier(v0: float, v3: float, s: float, t: float, h: float, u: float) -> float:
    v1, v2 = v0 + s * h / 3.0, v3 - t * h / 3.0
    return sum(c * math.comb(3, k) * u**k * (1 - u) ** (3 - k) for k, c in enumerate((v0, v1, v2, v3)))


def bezier_reference(zm: ZMap, x: float, y: float) -> float:
    """Circular-tangent Bezier height at one world point of a map with no NaN heights."""
    cell = _cell(zm, x, y)
    if cell is None:
        return math.nan
    i, j, u, v = cell

    def zat(a: int, b: int):
        return float(zm.z[a, b]) if 0 <= a < zm.nx and 0 <= b < zm.ny else None

    def slopes(line: list, h: float) -> tuple[float, float]:
        # line = heights at offsets -1, 0, 1, 2; slopes at offsets 0 and 1.
        w = _line_heights(line)
        s = _circle_slope((-h, w[0]), (0.0, w[1]), (h, w[2]))
        t = _circle_slope((0.0, w[1]), (h, w[2]), (2 * h, w[3]))
        return s, t

    w = []
    for jj in (j, j + 1):  # W1 from g1..g4, W2 from g5..g8
        line = [zat(i - 1, jj), zat(i, jj), zat(i + 1, jj), zat(i + 2, jj)]
        s, t = slopes(line, zm.dx)
        w.append(_bezier(line[1], line[2], s, t, zm.dx, u))
    w34 = []
    for ii in (i, i + 1):  # W3 from g9, g2, g6, g10 and W4 from g11, g3, g7, g12
        line = [zat(ii, j - 1), zat(ii, j), zat(ii, j + 1), zat(ii, j + 2)]
        s, t = slopes(line, zm.dy)
        w34.append(_bezier(w[0], w[1], s, t, zm.dy, v))
    return (1 - u) * w34[0] + u * w34[1]


def bilinear_reference(zm: ZMap, x: float, y: float) -> float:
    """Bilinear height at one world point."""
    cell = _cell(zm, x, y)
    if cell is None:
        return math.nan
    i, j, u, v = cell
    z = zm.z
    return ((1 - u) * (1 - v) * z[i, j] + u * (1 - v) * z[i + 1, j]
            + (1 - u) * v * z[i, j + 1] + u * v * z[i + 1, j + 1])
