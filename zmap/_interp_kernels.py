"""Numba kernels behind :mod:`zmap.interpolate`. No validation here: callers own the API.

Every kernel takes the heights ``z`` (nx, ny) C-contiguous float64, the grid
``x0, y0, dx, dy``, the local frame ``(cos, sin, ox, oy)``, flat float64 query arrays and a
preallocated ``out``; it writes NaN where the answer is undefined.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

# Tangent schemes (paper 004 Eq. 5 uses the circular tangent).
TANGENT_CIRCLE = 0
TANGENT_CENTRAL = 1
TANGENT_QUARTIC = 2
# Boundary treatment at the edge of the grid domain.
BOUNDARY_DUMMY = 0  # paper §2.2: dummy grid points by linear extrapolation
BOUNDARY_ONE_SIDED = 1  # one-sided tangents, as inside the map next to a missing height

# Points a hair outside the domain (rounding in x0 + i*dx) still count as on its edge.
_EDGE_SLACK = 1e-9


@njit(cache=True)
def _circle_tangent_slope(ax: float, az: float, bx: float, bz: float) -> float:
    """Slope at the origin of the circle through (0,0), (ax,az), (bx,bz).

    Falls back to the slope of the parabola through the three points where they are
    collinear or the circle's tangent there is vertical.
    """
    det = ax * bz - az * bx
    ra = 0.5 * (ax * ax + az * az)
    rb = 0.5 * (bx * bx + bz * bz)
    # Parabola through the same points, as the well-conditioned fallback.
    parab = (az * bx * bx - bz * ax * ax) / (ax * bx * (bx - ax))
    scale = max(abs(ax * bz), abs(az * bx), 1e-300)
    if abs(det) <= 1e-14 * scale:
        return parab
    cx = (ra * bz - az * rb) / det
    cz = (ax * rb - bx * ra) / det
    if cz == 0.0:
        return parab
    return -cx / cz


@njit(cache=True)
def _centred_circle_slope(p: float, q: float, h: float) -> float:
    """Slope at the middle point of the circle through (-h, z-p), (0, z), (h, z+q).

    Closed form of the circle's tangent; equals q/h for collinear points.
    """
    return (p + q) * (h * h + p * q) / (h * (2.0 * h * h + p * p + q * q))


@njit(cache=True)
def _height(z, i, j, nx, ny):
    """Height at (i, j), NaN outside the grid."""
    if i < 0 or i >= nx or j < 0 or j >= ny:
        return np.nan
    return z[i, j]


@njit(cache=True)
def _slope(z, i, j, di, dj, h, nx, ny, tangent, boundary):
    """Slope dz/ds at grid point (i, j) along the axis (di, dj), grid interval h.

    Uses the widest complete stencil: centred (circle, central or fourth-order), then a
    one-sided three-point tangent, then the secant to the one neighbour that exists.
    """
    z0 = z[i, j]
    zm1 = _height(z, i - di, j - dj, nx, ny)
    zp1 = _height(z, i + di, j + dj, nx, ny)
    if boundary == BOUNDARY_DUMMY:
        # A neighbour beyond the grid's edge is a dummy point on the line through the two
        # nearest grid points (paper §2.2); a NaN inside the grid stays missing.
        k = i * di + j * dj
        n = nx if di == 1 else ny
        if k == 0 and not math.isnan(zp1):
            zm1 = 2.0 * z0 - zp1
        elif k == n - 1 and not math.isnan(zm1):
            zp1 = 2.0 * z0 - zm1
    has_m = not math.isnan(zm1)
    has_p = not math.isnan(zp1)
    if has_m and has_p:
        if tangent == TANGENT_CIRCLE:
            return _centred_circle_slope(z0 - zm1, zp1 - z0, h)
        if tangent == TANGENT_QUARTIC:
            zm2 = _height(z, i - 2 * di, j - 2 * dj, nx, ny)
            zp2 = _height(z, i + 2 * di, j + 2 * dj, nx, ny)
            if not (math.isnan(zm2) or math.isnan(zp2)):
                return (zm2 - 8.0 * zm1 + 8.0 * zp1 - zp2) / (12.0 * h)
        return (zp1 - zm1) / (2.0 * h)
    if has_p:
        zp2 = _height(z, i + 2 * di, j + 2 * dj, nx, ny)
        if math.isnan(zp2):
            return (zp1 - z0) / h
        parab = (-3.0 * z0 + 4.0 * zp1 - zp2) / (2.0 * h)
        if tangent == TANGENT_CIRCLE:
            return _bounded_end_slope(_circle_tangent_slope(h, zp1 - z0, 2.0 * h, zp2 - z0), (zp1 - z0) / h, parab)
        return parab
    if has_m:
        zm2 = _height(z, i - 2 * di, j - 2 * dj, nx, ny)
        if math.isnan(zm2):
            return (z0 - zm1) / h
        parab = (3.0 * z0 - 4.0 * zm1 + zm2) / (2.0 * h)
        if tangent == TANGENT_CIRCLE:
            return _bounded_end_slope(_circle_tangent_slope(-h, zm1 - z0, -2.0 * h, zm2 - z0), (z0 - zm1) / h, parab)
        return parab
    return 0.0


@njit(cache=True)
def _bounded_end_slope(circle, secant, parab):
    """The circle's tangent at an end point, unless it leaves the band [0, 3] x the secant.

    A circle through three steep heights can have a nearly vertical (or backward) tangent at
    its end point, and the non-parametric cubic would then overshoot by orders of
    magnitude. Slopes between 0 and 3 times the secant keep the cubic monotone across the
    cell (Fritsch and Carlson); outside that band the parabola's end slope is used.
    """
    if secant != 0.0:
        r = circle / secant
        if r >= 0.0 and r <= 3.0:
            return circle
    return parab


@njit(cache=True)
def _bezier1d(a, b, s, t, h, u):
    """Non-parametric cubic Bezier (Eq. 5-6): v0=a, v1=a+s*h/3, v2=b-t*h/3, v3=b."""
    v1 = a + s * h / 3.0
    v2 = b - t * h / 3.0
    w = 1.0 - u
    return w * w * w * a + 3.0 * w * w * u * v1 + 3.0 * w * u * u * v2 + u * u * u * b


@njit(cache=True)
def _to_local(x, y, c, s, ox, oy):
    """A world point in a map's frame (rotated by the angle of cosine ``c``, sine ``s``
    about the origin ``(ox, oy)``), as ``ZMap.to_local``."""
    px = x - ox
    py = y - oy
    return c * px + s * py, -s * px + c * py


@njit(cache=True)
def _locate(x, y, x0, y0, dx, dy, c, s, ox, oy, nx, ny):
    """Cell (i, j) and local (u, v) of a world point; i = -1 when outside the domain."""
    lx, ly = _to_local(x, y, c, s, ox, oy)
    fi = (lx - x0) / dx
    fj = (ly - y0) / dy
    if not (fi >= -_EDGE_SLACK and fi <= nx - 1 + _EDGE_SLACK and fj >= -_EDGE_SLACK and fj <= ny - 1 + _EDGE_SLACK):
        return -1, -1, 0.0, 0.0
    i = int(math.floor(fi))
    j = int(math.floor(fj))
    i = min(max(i, 0), nx - 2)
    j = min(max(j, 0), ny - 2)
    u = min(max(fi - i, 0.0), 1.0)
    v = min(max(fj - j, 0.0), 1.0)
    return i, j, u, v


@njit(cache=True)
def _bezier_cell(z, i, j, u, v, dx, dy, nx, ny, tangent, boundary):
    """Paper 004 Eq. 4-7 in cell (i, j) of ``z`` at cell coordinates (u, v); NaN at a missing corner.

    ``z`` may be a window of a larger map (:mod:`zmap.tiled`): ``nx``, ``ny`` are then the
    window's, and the slopes' edge rules act only at its edges.
    """
    if math.isnan(z[i, j]) or math.isnan(z[i + 1, j]) or math.isnan(z[i, j + 1]) or math.isnan(z[i + 1, j + 1]):
        return np.nan
    return _bezier_patch(z[i, j], z[i + 1, j], z[i, j + 1], z[i + 1, j + 1],
                         _slope(z, i, j, 1, 0, dx, nx, ny, tangent, boundary),
                         _slope(z, i + 1, j, 1, 0, dx, nx, ny, tangent, boundary),
                         _slope(z, i, j + 1, 1, 0, dx, nx, ny, tangent, boundary),
                         _slope(z, i + 1, j + 1, 1, 0, dx, nx, ny, tangent, boundary),
                         _slope(z, i, j, 0, 1, dy, nx, ny, tangent, boundary),
                         _slope(z, i, j + 1, 0, 1, dy, nx, ny, tangent, boundary),
                         _slope(z, i + 1, j, 0, 1, dy, nx, ny, tangent, boundary),
                         _slope(z, i + 1, j + 1, 0, 1, dy, nx, ny, tangent, boundary), dx, dy, u, v)


@njit(cache=True)
def _bezier_patch(z2, z3, z6, z7, sx2, sx3, sx6, sx7, sy2, sy6, sy3, sy7, dx, dy, u, v):
    """Eq. 4-7 from a cell's corner heights (z2 at (i, j), z3 at (i + 1, j), z6 at (i, j + 1),
    z7 at (i + 1, j + 1)) and their slopes along x (sx) and y (sy)."""
    # x-direction curves V1 (row j) and V2 (row j+1), evaluated at u.
    w1 = _bezier1d(z2, z3, sx2, sx3, dx, u)
    w2 = _bezier1d(z6, z7, sx6, sx7, dx, u)
    # y-direction curves V3 (column i) and V4 (column i+1) between w1 and w2, at v.
    w3 = _bezier1d(w1, w2, sy2, sy6, dy, v)
    w4 = _bezier1d(w1, w2, sy3, sy7, dy, v)
    return (1.0 - u) * w3 + u * w4


@njit(cache=True)
def slope_tables(z, dx, dy, tangent, boundary, sx, sy):
    """The slopes of every node of ``z`` along x (``sx``) and y (``sy``), as :func:`_bezier_cell`
    takes them: with them :func:`bezier_cell_tabled` gives its heights for a fraction of the
    work (a cell's eight slopes are most of it)."""
    nx, ny = z.shape
    for i in range(nx):
        for j in range(ny):
            sx[i, j] = _slope(z, i, j, 1, 0, dx, nx, ny, tangent, boundary)
            sy[i, j] = _slope(z, i, j, 0, 1, dy, nx, ny, tangent, boundary)


@njit(cache=True)
def bezier_cell_tabled(z, sx, sy, i, j, u, v, dx, dy):
    """:func:`_bezier_cell` with the slopes of :func:`slope_tables` (the same bits)."""
    if math.isnan(z[i, j]) or math.isnan(z[i + 1, j]) or math.isnan(z[i, j + 1]) or math.isnan(z[i + 1, j + 1]):
        return np.nan
    return _bezier_patch(z[i, j], z[i + 1, j], z[i, j + 1], z[i + 1, j + 1], sx[i, j], sx[i + 1, j], sx[i, j + 1],
                         sx[i + 1, j + 1], sy[i, j], sy[i, j + 1], sy[i + 1, j], sy[i + 1, j + 1], dx, dy, u, v)


@njit(cache=True)
def _bilinear_cell(z, i, j, u, v):
    """Bilinear interpolation in cell (i, j) of ``z`` at cell coordinates (u, v)."""
    return ((1.0 - u) * ((1.0 - v) * z[i, j] + v * z[i, j + 1])
            + u * ((1.0 - v) * z[i + 1, j] + v * z[i + 1, j + 1]))


@njit(cache=True, parallel=True)
def bezier_kernel(z, x0, y0, dx, dy, c, s, ox, oy, xs, ys, tangent, boundary, out):
    """Paper 004 Eq. 4-7 at every query point."""
    nx, ny = z.shape
    for k in prange(xs.shape[0]):
        i, j, u, v = _locate(xs[k], ys[k], x0, y0, dx, dy, c, s, ox, oy, nx, ny)
        out[k] = np.nan if i < 0 else _bezier_cell(z, i, j, u, v, dx, dy, nx, ny, tangent, boundary)


@njit(cache=True, parallel=True)
def bilinear_kernel(z, x0, y0, dx, dy, c, s, ox, oy, xs, ys, out):
    """Bilinear interpolation in the cell holding each query point."""
    nx, ny = z.shape
    for k in prange(xs.shape[0]):
        i, j, u, v = _locate(xs[k], ys[k], x0, y0, dx, dy, c, s, ox, oy, nx, ny)
        out[k] = np.nan if i < 0 else _bilinear_cell(z, i, j, u, v)