"""Numba kernels behind :mod:`zmap.model`. No validation here: callers own the API.

CZ-maps are packed flat: heights of map ``m`` are ``cz_z[cz_off[m]:cz_off[m+1]]`` in C order
of shape ``cz_shape[m]``, its grid and frame ``cz_par[m] = (x0, y0, dx, dy, cos, sin, ox, oy)``.
Per base cell ``c = i * (ny - 1) + j`` the CZ-maps whose domain meets the cell are
``cell_cz[cell_ptr[c]:cell_ptr[c+1]]``.
"""

from __future__ import annotations


import numpy as np
from numba import njit, prange

from ._interp_kernels import _EDGE_SLACK, _bezier_cell, _locate, _to_local, bezier_cell_tabled

__all__ = ["model_heights", "bezier_at", "bezier_at_tabled"]


@njit(cache=True)
def bezier_at(z, x0, y0, dx, dy, c, s, ox, oy, x, y, tangent, boundary):
    """Paper 004 Eq. 4-7 at one world point on one map; NaN outside or on a missing corner."""
    nx, ny = z.shape
    i, j, u, v = _locate(x, y, x0, y0, dx, dy, c, s, ox, oy, nx, ny)
    return np.nan if i < 0 else _bezier_cell(z, i, j, u, v, dx, dy, nx, ny, tangent, boundary)


@njit(cache=True)
def bezier_at_tabled(z, sx, sy, x0, y0, dx, dy, c, s, ox, oy, x, y):
    """:func:`bezier_at` with the map's slope tables (:func:`zmap._interp_kernels.slope_tables`)."""
    nx, ny = z.shape
    i, j, u, v = _locate(x, y, x0, y0, dx, dy, c, s, ox, oy, nx, ny)
    return np.nan if i < 0 else bezier_cell_tabled(z, sx, sy, i, j, u, v, dx, dy)


@njit(cache=True)
def deepest_cz(x, y, cell, cell_ptr, cell_cz, cz_par, cz_shape):
    """The CZ-map of ``cell``'s list in which world point (x, y) lies deepest; -1 if none holds it."""
    best = -1
    depth = -1.0
    for q in range(cell_ptr[cell], cell_ptr[cell + 1]):
        m = cell_cz[q]
        # cz_par[m] = (x0, y0, dx, dy, cos, sin, ox, oy)
        lx, ly = _to_local(x, y, cz_par[m, 4], cz_par[m, 5], cz_par[m, 6], cz_par[m, 7])
        lo_x = cz_par[m, 0]
        lo_y = cz_par[m, 1]
        dx = cz_par[m, 2]
        dy = cz_par[m, 3]
        d = min(min(lx - lo_x, lo_x + (cz_shape[m, 0] - 1) * dx - lx),
                min(ly - lo_y, lo_y + (cz_shape[m, 1] - 1) * dy - ly))
        if d >= -_EDGE_SLACK * min(dx, dy) and d > depth:
            depth = d
            best = m
    return best


@njit(cache=True, parallel=True)
def model_heights(bz, bx0, by0, bdx, bdy, bc, bs, box, boy, cz_z, cz_off, cz_shape, cz_par,
                  cell_ptr, cell_cz, ez_cell, xs, ys, tangent, boundary, out, src):
    """Height of every query point: its best CZ-map, else (flag) an EZ cell, else the base.

    ``src[k]``: 0 no height, 1 base, 2 CZ-map, 3 EZ cell (the caller evaluates the EZ-map
    there and writes ``out[k]``; the base height is left in ``out[k]`` as its fallback).
    Among the CZ-maps whose domain holds the point, the one in which the point lies
    deepest (largest distance to the domain's border, in its local frame) answers.
    """
    nx, ny = bz.shape
    for k in prange(xs.shape[0]):
        x = xs[k]
        y = ys[k]
        i, j, u, v = _locate(x, y, bx0, by0, bdx, bdy, bc, bs, box, boy, nx, ny)
        if i < 0:
            out[k] = np.nan
            src[k] = 0
            continue
        cell = i * (ny - 1) + j
        best = deepest_cz(x, y, cell, cell_ptr, cell_cz, cz_par, cz_shape)
        if best >= 0:
            zz = cz_z[cz_off[best]:cz_off[best + 1]].reshape((cz_shape[best, 0], cz_shape[best, 1]))
            h = bezier_at(zz, cz_par[best, 0], cz_par[best, 1], cz_par[best, 2], cz_par[best, 3],
                          cz_par[best, 4], cz_par[best, 5], cz_par[best, 6], cz_par[best, 7], x, y,
                          tangent, boundary)
            if h == h:
                out[k] = h
                src[k] = 2
                continue
        out[k] = bezier_at(bz, bx0, by0, bdx, bdy, bc, bs, box, boy, x, y, tangent, boundary)
        if ez_cell[cell]:
            src[k] = 3
        elif out[k] == out[k]:
            src[k] = 1
        else:
            src[k] = 0
