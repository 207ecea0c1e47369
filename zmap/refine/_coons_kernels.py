"""Numba kernels of an e-cell's four boundary curves and their Coons patch (conventions:
:mod:`zmap.refine._ez_kernels`).

An e-edge's curve runs linearly through its samples and, across its break, each side is
extended from its own last two (:func:`_edge_value`); an edge without e-points is the base's
cubic Bezier along it, its end slopes taken from the side away from a break
(:func:`plain_edge_slopes`). A cell that no trace splits is the bilinearly blended Coons
patch of its four curves (:func:`_coons`, :func:`coons_blend`). No validation here.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .._interp_kernels import (
    BOUNDARY_DUMMY,
    TANGENT_CIRCLE,
    _bezier1d,
    _circle_tangent_slope,
    _slope,
)
from ._edge_kernels import BREAK_NONE, _sample

__all__ = ["_coons", "_edge_nodes", "_edge_slope", "_edge_value", "_edge_xy", "_find", "coons_blend",
           "plain_edge_slopes"]


@njit(cache=True, error_model="numpy")
def _grid_edge(i, j, di, nx, ny):
    """Global id of the edge from (i, j) one step along x (di=1) or y (di=0); -1 outside."""
    if di == 1:
        if i < 0 or i > nx - 2 or j < 0 or j > ny - 1:
            return -1
        return i * ny + j
    if i < 0 or i > nx - 1 or j < 0 or j > ny - 2:
        return -1
    return (nx - 1) * ny + i * (ny - 1) + j


@njit(cache=True, error_model="numpy")
def _broken(edge_ids, brk_kind, eid):
    if eid < 0:
        return False
    k = _find(edge_ids, eid)
    return k >= 0 and brk_kind[k] != BREAK_NONE


@njit(cache=True, error_model="numpy")
def _edge_slope(z, i, j, di, dj, h, outer, edge_ids, brk_kind):
    """The base's slope at (i, j) along the axis, unless its stencil reaches across a break.

    ``outer`` (-1 or +1) is the side of (i, j) away from the plain edge being drawn. Where
    the edge on that side carries a break (a wall or a sharp edge), the slope comes from
    the plain side only: the one-sided circle tangent, else the secant.
    """
    nx, ny = z.shape
    if outer < 0:
        eo = _grid_edge(i - di, j - dj, di, nx, ny)
    else:
        eo = _grid_edge(i, j, di, nx, ny)
    if not _broken(edge_ids, brk_kind, eo):
        return _slope(z, i, j, di, dj, h, nx, ny, TANGENT_CIRCLE, BOUNDARY_DUMMY)
    s = -outer  # the plain side
    z0 = z[i, j]
    z1 = z[i + s * di, j + s * dj]
    i2 = i + 2 * s * di
    j2 = j + 2 * s * dj
    if 0 <= i2 < nx and 0 <= j2 < ny and not math.isnan(z[i2, j2]):
        if s > 0:
            e2 = _grid_edge(i + di, j + dj, di, nx, ny)
        else:
            e2 = _grid_edge(i2, j2, di, nx, ny)
        if not _broken(edge_ids, brk_kind, e2):
            return _circle_tangent_slope(s * h, z1 - z0, 2.0 * s * h, z[i2, j2] - z0)
    return (z1 - z0) / (s * h)


@njit(cache=True, error_model="numpy")
def _edge_nodes(i, j, k):
    """The grid nodes (ia, ja) and (ib, jb) at the ends of local edge ``k`` of cell (i, j)
    (0 bottom, 1 right, 2 top, 3 left; each from its low end)."""
    if k == 0:
        return i, j, i + 1, j
    if k == 1:
        return i + 1, j, i + 1, j + 1
    if k == 2:
        return i, j + 1, i + 1, j + 1
    return i, j, i, j + 1


@njit(cache=True, error_model="numpy")
def plain_edge_slopes(z, i, j, k, edge_ids, brk_kind, dx, dy):
    """The slopes at the ends of local edge ``k`` of cell (i, j) along it, for an edge without
    e-points (:func:`_edge_value`: the base's cubic Bezier along it, with the slopes of
    :func:`_edge_slope`)."""
    ia, ja, ib, jb = _edge_nodes(i, j, k)
    if k == 0 or k == 2:
        return (_edge_slope(z, ia, ja, 1, 0, dx, -1, edge_ids, brk_kind),
                _edge_slope(z, ib, jb, 1, 0, dx, 1, edge_ids, brk_kind))
    return (_edge_slope(z, ia, ja, 0, 1, dy, -1, edge_ids, brk_kind),
            _edge_slope(z, ib, jb, 0, 1, dy, 1, edge_ids, brk_kind))


@njit(cache=True, error_model="numpy")
def _edge_value(z, i, j, k, t, side, slot, edge_ids, offsets, hq, brk_kind, brk_t, dx, dy):
    """Boundary curve of local edge ``k`` of cell (i, j) at parameter t.

    An e-edge interpolates its sequence linearly; across its break, each side is extended
    from its own last two samples (``side`` -1 low t, +1 high t, 0 by t). An edge without
    e-points is the base's cubic Bezier along it (as the base evaluates it).
    """
    ia, ja, ib, jb = _edge_nodes(i, j, k)
    if slot < 0:
        sa, sb = plain_edge_slopes(z, i, j, k, edge_ids, brk_kind, dx, dy)
        return _bezier1d(z[ia, ja], z[ib, jb], sa, sb, dx if k == 0 or k == 2 else dy, t)
    off = offsets[slot]
    n = offsets[slot + 1] - off
    m = n + 1
    f = t * m
    q = math.floor(f)
    q = min(max(q, 0), m - 1)
    if brk_kind[slot] != BREAK_NONE:
        tb = brk_t[slot] * m
        lo = math.floor(tb + 1e-9)
        hi = math.ceil(tb - 1e-9)
        lo = min(max(lo, 0), m)
        hi = min(max(hi, 0), m)
        low = f <= tb if side == 0 else side < 0
        if low:
            if q + 1 > lo:
                zl = _sample(z, hq, slot, off, n, ia, ja, ib, jb, lo)
                if lo >= 1:
                    return zl + (zl - _sample(z, hq, slot, off, n, ia, ja, ib, jb, lo - 1)) * (f - lo)
                return zl
        else:
            if q < hi:
                zh = _sample(z, hq, slot, off, n, ia, ja, ib, jb, hi)
                if hi + 1 <= m:
                    return zh + (_sample(z, hq, slot, off, n, ia, ja, ib, jb, hi + 1) - zh) * (f - hi)
                return zh
    za = _sample(z, hq, slot, off, n, ia, ja, ib, jb, q)
    zb = _sample(z, hq, slot, off, n, ia, ja, ib, jb, q + 1)
    return za + (f - q) * (zb - za)


@njit(cache=True, error_model="numpy")
def _edge_xy(k, t, dx, dy):
    if k == 0:
        return t * dx, 0.0
    if k == 1:
        return dx, t * dy
    if k == 2:
        return t * dx, dy
    return 0.0, t * dy


@njit(cache=True, error_model="numpy")
def _find(sorted_ids, key):
    c = np.searchsorted(sorted_ids, key)
    if c < sorted_ids.shape[0] and sorted_ids[c] == key:
        return c
    return -1


@njit(cache=True, error_model="numpy")
def _coons(z, i, j, u, v, c, slots, edge_ids, offsets, hq, brk_kind, brk_t, dx, dy, broken, bub):
    """Bilinearly blended Coons patch of the cell's four boundary curves, plus ``bub`` times
    the bubble ``16 u (1-u) v (1-v)`` (the cell's centre height correction, 0 for none);
    ``broken`` (a cell with breaks but no single trace) clamps it to the range of the four
    curves."""
    bot = _edge_value(z, i, j, 0, u, 0, slots[c, 0], edge_ids, offsets, hq, brk_kind, brk_t, dx, dy)
    rgt = _edge_value(z, i, j, 1, v, 0, slots[c, 1], edge_ids, offsets, hq, brk_kind, brk_t, dx, dy)
    top = _edge_value(z, i, j, 2, u, 0, slots[c, 2], edge_ids, offsets, hq, brk_kind, brk_t, dx, dy)
    lft = _edge_value(z, i, j, 3, v, 0, slots[c, 3], edge_ids, offsets, hq, brk_kind, brk_t, dx, dy)
    return coons_blend(z, i, j, u, v, bot, rgt, top, lft, broken, bub)


@njit(cache=True, error_model="numpy")
def coons_blend(z, i, j, u, v, bot, rgt, top, lft, broken, bub):
    """:func:`_coons` from the values of the cell's four boundary curves at (u, v)."""
    bil = ((1.0 - u) * ((1.0 - v) * z[i, j] + v * z[i, j + 1])
           + u * ((1.0 - v) * z[i + 1, j] + v * z[i + 1, j + 1]))
    h = (1.0 - v) * bot + v * top + (1.0 - u) * lft + u * rgt - bil
    if bub != 0.0:
        h += bub * 16.0 * u * (1.0 - u) * v * (1.0 - v)
    if broken:
        # boundary curves with jumps at unmatched places: keep within their values
        lo = min(min(bot, top), min(lft, rgt))
        hi = max(max(bot, top), max(lft, rgt))
        h = min(max(h, lo), hi)
    return h
