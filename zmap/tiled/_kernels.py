"""Numba kernels behind :mod:`zmap.tiled`: height queries on a window of a tiled map.

A window is the block ``z[a:a+wx, b:b+wy]`` of the whole map, read from the store with the
2-node stencil halo around the tile the query points fall in. Each kernel locates the point
on the *whole* grid (``x0, y0, nx, ny``: the same arithmetic as :mod:`zmap._interp_kernels`,
so the cell and ``(u, v)`` are the in-memory ones to the last bit), then evaluates the
in-memory kernels' own stencil helpers on the window, with indices shifted by ``(a, b)``.
Where the window stops inside the map, every stencil node a point of the tile needs lies
inside it (the halo), so the edge rules of the window never act; where it stops at the map's
edge, they are the map's own. No validation here: :mod:`zmap.tiled.store` owns the API.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .._interp_kernels import _bezier_cell, _bilinear_cell, _locate

__all__ = ["locate_cells", "bezier_window", "bilinear_window"]


@njit(cache=True, parallel=True)
def locate_cells(x0, y0, dx, dy, c, s, ox, oy, nx, ny, xs, ys, ci, cj):
    """Cell ``(ci, cj)`` of every query point on the whole grid; -1 outside the map."""
    for k in prange(xs.shape[0]):
        i, j, u, v = _locate(xs[k], ys[k], x0, y0, dx, dy, c, s, ox, oy, nx, ny)
        ci[k] = i
        cj[k] = j


@njit(cache=True, parallel=True)
def bezier_window(w, a, b, x0, y0, dx, dy, c, s, ox, oy, nx, ny, xs, ys, idx, tangent, boundary, out):
    """Bezier heights (paper 004 Eq. 4-7) of the points ``idx`` into ``out[idx]``.

    ``w`` is ``z[a:a+wx, b:b+wy]`` of the whole ``nx`` x ``ny`` map; every point of ``idx``
    lies in a cell whose stencil (2 nodes around it) the window holds.
    """
    wx, wy = w.shape
    for m in prange(idx.shape[0]):
        k = idx[m]
        i, j, u, v = _locate(xs[k], ys[k], x0, y0, dx, dy, c, s, ox, oy, nx, ny)
        out[k] = np.nan if i < 0 else _bezier_cell(w, i - a, j - b, u, v, dx, dy, wx, wy, tangent, boundary)


@njit(cache=True, parallel=True)
def bilinear_window(w, a, b, x0, y0, dx, dy, c, s, ox, oy, nx, ny, xs, ys, idx, out):
    """Bilinear heights of the points ``idx`` into ``out[idx]`` (window as in :func:`bezier_window`)."""
    for m in prange(idx.shape[0]):
        k = idx[m]
        i, j, u, v = _locate(xs[k], ys[k], x0, y0, dx, dy, c, s, ox, oy, nx, ny)
        out[k] = np.nan if i < 0 else _bilinear_cell(w, i - a, j - b, u, v)
