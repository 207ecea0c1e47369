"""Numba kernels that lay out and thin the e-edges' sequences of float64 heights (before they
are coded; conventions: :mod:`zmap.refine._ez_kernels`).

The e-points' places (:func:`edge_points`), single low samples lifted (:func:`despike`), the
fewest evenly spaced knots that hold a smooth edge within a limit (:func:`decimate_counts`,
:func:`resample`) and the windows of wall edges, full samples around the jump and thinned
either side (:func:`window_counts`, :func:`window_resample`), for
:func:`zmap.refine._eedges.decimate`. No validation here: callers own the API.
"""

from __future__ import annotations

import math

from numba import njit, prange

from ._edge_kernels import _edge_corners, pack_window, unpack_window

__all__ = ["decimate_counts", "despike", "edge_points", "resample", "window_counts", "window_resample"]


@njit(cache=True, error_model="numpy")  # serial: parfor lowering of this body took minutes to compile on a cold cache
def edge_points(edge_ids, offsets, x0, y0, dx, dy, nx, ny, px, py):
    """Local xy of every e-point (preallocated ``px``, ``py`` of length offsets[-1])."""
    for k in prange(edge_ids.shape[0]):
        axis, ia, ja, _ib, _jb = _edge_corners(edge_ids[k], nx, ny)
        off = offsets[k]
        n = offsets[k + 1] - off
        for q in range(n):
            t = (q + 1.0) / (n + 1.0)
            if axis == 0:
                px[off + q] = x0 + (ia + t) * dx
                py[off + q] = y0 + ja * dy
            else:
                px[off + q] = x0 + ia * dx
                py[off + q] = y0 + (ja + t) * dy


@njit(cache=True, error_model="numpy")  # serial: parfor lowering of this body took minutes to compile on a cold cache
def despike(z, edge_ids, offsets, heights, thresh, out_count):
    """Lift every e-point that lies more than ``thresh`` below both neighbours of its
    sequence to the higher neighbour (a sample on a wall's line answered by a lower face);
    ``out_count[k]`` counts the points lifted on edge k. ``heights`` float64, in place."""
    nx, ny = z.shape
    for k in prange(edge_ids.shape[0]):
        _axis, ia, ja, ib, jb = _edge_corners(edge_ids[k], nx, ny)
        off = offsets[k]
        n = offsets[k + 1] - off
        cnt = 0
        for q in range(1, n + 1):
            zp = z[ia, ja] if q == 1 else heights[off + q - 2]
            zn = z[ib, jb] if q == n else heights[off + q]
            zq = heights[off + q - 1]
            if zq < zp - thresh and zq < zn - thresh:
                heights[off + q - 1] = max(zp, zn)
                cnt += 1
        out_count[k] = cnt


@njit(cache=True, error_model="numpy")
def _polyline(za0, zb0, heights, off, m, f):
    """The edge's full boundary sequence (corners and e-points at ``q = 0..m``) read
    linearly at fractional index ``f``."""
    q = min(max(int(math.floor(f)), 0), m - 1)
    va = za0 if q == 0 else heights[off + q - 1]
    vb = zb0 if q + 1 == m else heights[off + q]
    return va + (vb - va) * (f - q)


@njit(cache=True, error_model="numpy")
def _next_count(d):
    """The next number of intervals tried after ``d`` (2, 3, 4, 5, 6, 8, 10, 12, 16, ...: steps of
    about 25 %)."""
    return max(d + 1, (d * 5) // 4)


@njit(cache=True, error_model="numpy")  # serial: parfor lowering of this body took minutes to compile on a cold cache
def decimate_counts(z, edge_ids, offsets, heights, limit, d0, out_m):
    """Fewest intervals ``d`` (``d0`` = 1 or 2, then 2, 3, 4, 5, 6, 8, ... below the edge's
    ``m = n + 1``) such that the edge's full sequence read at ``t = k / d`` and interpolated
    linearly between those knots is within ``limit`` of every full sample; ``m`` where none
    is or a sample or corner has no height. ``heights`` float64 (P,), ``out_m`` int64 (E,)."""
    nx, ny = z.shape
    for k in prange(edge_ids.shape[0]):
        _axis, ia, ja, ib, jb = _edge_corners(edge_ids[k], nx, ny)
        off = offsets[k]
        n = offsets[k + 1] - off
        m = n + 1
        out_m[k] = m
        za0 = z[ia, ja]
        zb0 = z[ib, jb]
        if math.isnan(za0) or math.isnan(zb0):
            continue
        ok = True
        for q in range(n):
            if math.isnan(heights[off + q]):
                ok = False
                break
        if not ok:
            continue
        d = d0
        while d < m:
            good = True
            for q in range(1, m):
                g = q * d / m  # the full sample's position among the knots
                a = min(int(math.floor(g)), d - 1)
                ka = _polyline(za0, zb0, heights, off, m, a * m / d)
                kb = _polyline(za0, zb0, heights, off, m, (a + 1) * m / d)
                if abs(ka + (kb - ka) * (g - a) - heights[off + q - 1]) > limit:
                    good = False
                    break
            if good:
                out_m[k] = d
                break
            d = _next_count(d)


@njit(cache=True, error_model="numpy")  # serial: parfor lowering of this body took minutes to compile on a cold cache
def resample(z, edge_ids, offsets, heights, counts, new_offsets, out):
    """The knots of :func:`decimate_counts`: edge k's full sequence read at ``t = q / (c + 1)``,
    ``q = 1..c`` (``c = counts[k]`` interior points), into ``out[new_offsets[k]:]``; an edge
    that keeps its count is copied, one with ``c < 0`` left alone."""
    nx, ny = z.shape
    for k in prange(edge_ids.shape[0]):
        if counts[k] < 0:
            continue
        _axis, ia, ja, ib, jb = _edge_corners(edge_ids[k], nx, ny)
        off = offsets[k]
        m = offsets[k + 1] - off + 1
        c = counts[k]
        d = c + 1
        o = new_offsets[k]
        if d == m:
            for q in range(c):
                out[o + q] = heights[off + q]
            continue
        for q in range(c):
            out[o + q] = _polyline(z[ia, ja], z[ib, jb], heights, off, m, (q + 1) * m / d)


@njit(cache=True, error_model="numpy")
def _span_count(za0, zb0, heights, off, m, s0, s1, limit):
    """Fewest intervals ``d`` (1, 2, 3, 4, 5, 6, 8, ...) over the full samples ``s0..s1`` such
    that the full sequence read at ``s0 + k (s1 - s0) / d`` and interpolated linearly
    between those knots is within ``limit`` of every full sample between; ``s1 - s0`` where
    none is."""
    L = s1 - s0
    if L <= 1:
        return L
    d = 1
    while d < L:
        good = True
        for q in range(s0 + 1, s1):
            g = (q - s0) * d / L
            a = min(int(math.floor(g)), d - 1)
            ka = _polyline(za0, zb0, heights, off, m, s0 + a * L / d)
            kb = _polyline(za0, zb0, heights, off, m, s0 + (a + 1) * L / d)
            if abs(ka + (kb - ka) * (g - a) - heights[off + q - 1]) > limit:
                good = False
                break
        if good:
            return d
        d = _next_count(d)
    return L


@njit(cache=True, error_model="numpy")  # serial: parfor lowering of this body took minutes to compile on a cold cache
def window_counts(z, edge_ids, offsets, heights, brk_t, sel, half, limit, out_win):
    """Windows of the wall edges ``sel`` (jump at ``brk_t``): the full samples from ``half``
    before the jump's interval to ``half`` after it are kept, each side of them thinned to
    the fewest knots within ``limit`` (:func:`_span_count`); ``out_win[k]`` packed
    (:func:`pack_window`), -1 where the edge or a corner has a NaN height."""
    nx, ny = z.shape
    for r in prange(sel.shape[0]):
        k = sel[r]
        _axis, ia, ja, ib, jb = _edge_corners(edge_ids[k], nx, ny)
        off = offsets[k]
        n = offsets[k + 1] - off
        m = n + 1
        out_win[k] = -1
        za0 = z[ia, ja]
        zb0 = z[ib, jb]
        if math.isnan(za0) or math.isnan(zb0) or m >= 0x7FFF:
            continue
        ok = True
        for q in range(n):
            if math.isnan(heights[off + q]):
                ok = False
                break
        if not ok:
            continue
        b = min(max(int(math.floor(brk_t[k] * m)), 0), m - 1)  # the jump's interval b..b+1
        a = max(b - half, 0)
        c = min(b + 1 + half, m)
        dl = _span_count(za0, zb0, heights, off, m, 0, a, limit)
        dr = _span_count(za0, zb0, heights, off, m, c, m, limit)
        out_win[k] = pack_window(a, c, dl, dr)


@njit(cache=True, error_model="numpy")  # serial: parfor lowering of this body took minutes to compile on a cold cache
def window_resample(z, edge_ids, offsets, heights, win, new_offsets, out):
    """The stored samples of windowed edges (``win[k] >= 0``, :func:`_sample` reads them):
    left knots, window samples, right knots, read off the full sequence; into
    ``out[new_offsets[k]:]``. Other edges are left alone."""
    nx, ny = z.shape
    for k in prange(edge_ids.shape[0]):
        if win[k] < 0:
            continue
        _axis, ia, ja, ib, jb = _edge_corners(edge_ids[k], nx, ny)
        off = offsets[k]
        n = offsets[k + 1] - off
        m = n + 1
        a, c, dl, dr = unpack_window(win[k])
        o = new_offsets[k]
        for q in range(1, dl):
            out[o] = _polyline(z[ia, ja], z[ib, jb], heights, off, m, q * a / dl)
            o += 1
        for q in range(max(a, 1), min(c, n) + 1):
            out[o] = heights[off + q - 1]
            o += 1
        for q in range(1, dr):
            out[o] = _polyline(z[ia, ja], z[ib, jb], heights, off, m, c + q * (m - c) / dr)
            o += 1
