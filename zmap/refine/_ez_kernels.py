"""Numba kernels behind :mod:`zmap.refine.ez`. No validation here: callers own the API.

Conventions (see :class:`zmap.refine.ez.EZMap`):

- edge ids: x-edge ``(i, j)-(i+1, j)`` is ``i*ny + j``; y-edge ``(i, j)-(i, j+1)`` is
  ``(nx-1)*ny + i*(ny-1) + j``. Edge ``k`` of the e-map carries ``n = offsets[k+1] -
  offsets[k]`` interior samples at ``t = q/(n+1)``, ``q = 1..n``; with the two grid corners
  (``q = 0`` and ``q = n+1``) they form the edge's boundary sequence. The evaluation
  kernels take the *virtual* offsets (a windowed wall edge counts its full samples) and
  read samples through :func:`_sample`, whose ``hq = (codes, lo, step, cstart, win)``
  knows where each edge's codes start and how a windowed edge stores them.
- a cell ``(i, j)`` has id ``i*(ny-1) + j`` and local edges 0 bottom (+x), 1 right (+y),
  2 top (+x), 3 left (+y); its perimeter coordinate ``s`` runs counter-clockwise from the
  corner ``(i, j)``: bottom ``s = t``, right ``1 + t``, top ``2 + (1 - t)``, left
  ``3 + (1 - t)``. Cell-local coordinates are metric: ``(u*dx, v*dy)``.
- a break on an edge is a jump (kind 1, a vertical wall) or a kink (kind 2, a sharp edge)
  of its boundary sequence, at parameter ``brk_t``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .._interp_kernels import (
    BOUNDARY_DUMMY,
    TANGENT_CIRCLE,
    _bezier1d,
    _circle_tangent_slope,
    _locate,
    _slope,
)

BREAK_NONE = 0
BREAK_JUMP = 1
BREAK_KINK = 2
# 16-bit e-point code meaning 'no height' (valid codes are 0..NAN_CODE-1).
NAN_CODE = 65535

# A cell whose two boundary breaks turn by more than this is taken as holding a corner of
# the wall (trace through the corner), else as a smooth arc (trace through its midpoint).
CORNER_TURN = math.radians(30.0)
# A neighbouring crossing closer than this share of the grid interval does not steer the trace.
MIN_LEVER = 0.5
# Cells walked along the trace to find that crossing.
MAX_WALK = 4


@njit(cache=True, error_model="numpy")
def _edge_corners(eid, nx, ny):
    """(axis, ia, ja, ib, jb) of a global edge id; axis 0 = x-edge, 1 = y-edge."""
    nxe = (nx - 1) * ny
    if eid < nxe:
        i = eid // ny
        j = eid - i * ny
        return 0, i, j, i + 1, j
    r = eid - nxe
    i = r // (ny - 1)
    j = r - i * (ny - 1)
    return 1, i, j, i, j + 1


@njit(cache=True, error_model="numpy")
def _dec(hq, e, at):
    """Decoded code ``at`` of e-edge slot e: ``lo[e] + step[e] * code`` (NaN for ``NAN_CODE``)."""
    code = hq[0][at]
    if code == NAN_CODE:
        return np.nan
    return np.float64(hq[1][e]) + np.float64(hq[2][e]) * np.float64(code)


#: A windowed edge keeps its full samples from this many before its break's interval to
#: this many after it (:func:`window_counts`; the stored window is ``a = b - WINDOW_HALF``,
#: ``c = b + 1 + WINDOW_HALF`` for the break's interval ``b..b+1``, clipped to the edge).
WINDOW_HALF = 1
#: Flag bits a packed window may carry on its way into :class:`zmap.refine._emap.EZMap`
#: (bit 15 of ``a`` and of ``c``, both below 2**15): the edge's break is forced, and it is
#: a kink (else a jump). The map keeps them apart (``forced``), so ``hq``'s windows never
#: carry them.
WIN_FORCED = 1 << 15
WIN_KINK = 1 << 31


@njit(cache=True, error_model="numpy")
def unpack_window(w):
    """``(a, c, dl, dr)`` of a packed window (:func:`pack_window`), flags masked off."""
    return w & 0x7FFF, (w >> 16) & 0x7FFF, (w >> 32) & 0xFFFF, (w >> 48) & 0xFFFF


@njit(cache=True, error_model="numpy")
def window_break(w, m):
    """The first full sample ``b`` of the break's interval of a window ``w`` over ``m``
    intervals (inverse of :func:`window_counts`' ``a``, ``c``)."""
    a, c, _dl, _dr = unpack_window(w)
    b = a + WINDOW_HALF if a > 0 else c - 1 - WINDOW_HALF
    return min(max(b, 0), m - 1)


@njit(cache=True, error_model="numpy")
def pack_window(a, c, dl, dr):
    """One int64 of a wall edge's window: full samples ``a..c`` kept, ``dl`` intervals over
    ``[0, a]`` and ``dr`` over ``[c, m]`` (each < 2**15)."""
    return np.int64(a) | (np.int64(c) << 16) | (np.int64(dl) << 32) | (np.int64(dr) << 48)


@njit(cache=True, error_model="numpy")
def _sample(z, hq, e, off, n, ia, ja, ib, jb, q):
    """Sample q of the (virtual, full) sequence of e-edge slot e: grid corners at q = 0 and
    n+1, else the decoded e-point; ``hq`` is the tuple (codes, lo, step, cstart, win).

    ``cstart[e]`` is where the edge's codes start. ``win[e] < 0``: the edge stores its ``n``
    samples. Else it is a windowed wall edge (:func:`pack_window`): it stores ``dl - 1``
    knots over ``[0, a]``, the full samples ``a..c`` (those in ``1..n``) and ``dr - 1``
    knots over ``[c, n + 1]``; a sample outside the window is read linearly between the
    knots of its span, at its place in the full sequence (``off`` is unused here).
    """
    if q <= 0:
        return z[ia, ja]
    if q >= n + 1:
        return z[ib, jb]
    w = hq[4][e]
    cs = hq[3][e]
    if w < 0:
        return _dec(hq, e, cs + q - 1)
    a, c, dl, dr = unpack_window(w)
    nl = dl - 1 if dl > 0 else 0
    qlo = a if a >= 1 else 1
    if q >= a and q <= c:
        return _dec(hq, e, cs + nl + q - qlo)
    if q < a:
        g = q * dl / a
        k = min(int(math.floor(g)), dl - 1)
        va = z[ia, ja] if k == 0 else _dec(hq, e, cs + k - 1)
        vb = _dec(hq, e, cs + nl + a - qlo) if k + 1 == dl else _dec(hq, e, cs + k)
        return va + (vb - va) * (g - k)
    nw = min(c, n) - qlo + 1
    g = (q - c) * dr / (n + 1 - c)
    k = min(int(math.floor(g)), dr - 1)
    va = _dec(hq, e, cs + nl + c - qlo) if k == 0 else _dec(hq, e, cs + nl + nw + k - 1)
    vb = z[ib, jb] if k + 1 == dr else _dec(hq, e, cs + nl + nw + k)
    return va + (vb - va) * (g - k)


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


@njit(cache=True, error_model="numpy")
def window_size(win, n):
    """Codes a windowed edge of ``n`` full samples stores."""
    a, c, dl, dr = unpack_window(win)
    qlo = a if a >= 1 else 1
    return (dl - 1 if dl > 0 else 0) + (min(c, n) - qlo + 1) + (dr - 1 if dr > 0 else 0)


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


@njit(cache=True, error_model="numpy")  # serial: parfor lowering of this body took minutes to compile on a cold cache
def detect_breaks(z, edge_ids, offsets, hq, forced, jump_min, kink_min, ratio, out_kind, out_t):
    """One break per edge: the dominant jump, else the dominant kink, of its sequence.

    A jump is the interval whose rise exceeds its neighbours' by ``jump_min`` and is
    ``ratio`` times theirs; it is placed mid-interval. A kink is the sample pair whose second
    differences sum above ``kink_min`` and ``ratio`` times every other second difference;
    it is placed where the lines through the two samples on either side meet.

    A windowed edge with ``forced[k]`` (int8: 1 a jump, 2 a kink; 0 searched for) is not
    searched: its break is the full sequence's, of that kind, in the interval its window
    holds (:func:`window_break`); a kink is placed there by the same rule.
    """
    nx, ny = z.shape
    for k in prange(edge_ids.shape[0]):
        out_kind[k] = BREAK_NONE
        out_t[k] = -1.0
        _axis, ia, ja, ib, jb = _edge_corners(edge_ids[k], nx, ny)
        off = offsets[k]
        n = offsets[k + 1] - off
        m = n + 1
        ok = True
        for q in range(m + 1):
            if math.isnan(_sample(z, hq, k, off, n, ia, ja, ib, jb, q)):
                ok = False
                break
        if not ok or m < 2:
            continue
        w = hq[4][k]
        if w >= 0 and forced[k] != BREAK_NONE:
            # a forced break: the full sequence's, whose interval the window holds
            b = window_break(w, m)
            if forced[k] == BREAK_JUMP:
                out_kind[k] = BREAK_JUMP
                out_t[k] = (b + 0.5) / m
                continue
            a = max(b, 1)
            b = min(a + 1, m - 1)
            za = _sample(z, hq, k, off, n, ia, ja, ib, jb, a)
            zb = _sample(z, hq, k, off, n, ia, ja, ib, jb, b)
            sl = za - _sample(z, hq, k, off, n, ia, ja, ib, jb, a - 1)
            sr = _sample(z, hq, k, off, n, ia, ja, ib, jb, b + 1) - zb
            x = 0.5 * (a + b)
            if sl != sr:
                x = (zb - za + sl * a - sr * b) / (sl - sr)
            out_kind[k] = BREAK_KINK
            out_t[k] = min(max(x, float(a)), float(b)) / m
            continue
        # jump: the largest rise
        best = -1
        bval = -1.0
        for q in range(m):
            d = abs(_sample(z, hq, k, off, n, ia, ja, ib, jb, q + 1) - _sample(z, hq, k, off, n, ia, ja, ib, jb, q))
            if d > bval:
                bval = d
                best = q
        nb = 0.0
        if best > 0:
            nb = max(nb, abs(_sample(z, hq, k, off, n, ia, ja, ib, jb, best)
                             - _sample(z, hq, k, off, n, ia, ja, ib, jb, best - 1)))
        if best < m - 1:
            nb = max(nb, abs(_sample(z, hq, k, off, n, ia, ja, ib, jb, best + 2)
                             - _sample(z, hq, k, off, n, ia, ja, ib, jb, best + 1)))
        if bval - nb > jump_min and bval > ratio * nb:
            out_kind[k] = BREAK_JUMP
            out_t[k] = (best + 0.5) / m
            continue
        if m < 4:
            continue
        # kink: second differences D[q] at samples q = 1..m-1
        kbest = -1
        kval = -1.0
        for q in range(1, m):
            dd = abs(_sample(z, hq, k, off, n, ia, ja, ib, jb, q + 1) - 2.0 * _sample(z, hq, k, off, n, ia, ja, ib, jb, q)
                     + _sample(z, hq, k, off, n, ia, ja, ib, jb, q - 1))
            if dd > kval:
                kval = dd
                kbest = q
        dl = 0.0
        dr = 0.0
        if kbest - 1 >= 1:
            q = kbest - 1
            dl = abs(_sample(z, hq, k, off, n, ia, ja, ib, jb, q + 1) - 2.0 * _sample(z, hq, k, off, n, ia, ja, ib, jb, q)
                     + _sample(z, hq, k, off, n, ia, ja, ib, jb, q - 1))
        if kbest + 1 <= m - 1:
            q = kbest + 1
            dr = abs(_sample(z, hq, k, off, n, ia, ja, ib, jb, q + 1) - 2.0 * _sample(z, hq, k, off, n, ia, ja, ib, jb, q)
                     + _sample(z, hq, k, off, n, ia, ja, ib, jb, q - 1))
        if dl >= dr:
            a = kbest - 1
            total = kval + dl
        else:
            a = kbest
            total = kval + dr
        rest = 0.0
        for q in range(1, m):
            if q >= kbest - 1 and q <= kbest + 1:
                continue
            dd = abs(_sample(z, hq, k, off, n, ia, ja, ib, jb, q + 1) - 2.0 * _sample(z, hq, k, off, n, ia, ja, ib, jb, q)
                     + _sample(z, hq, k, off, n, ia, ja, ib, jb, q - 1))
            rest = max(rest, dd)
        if not (total > kink_min and total > ratio * rest):
            continue
        a = max(a, 1)
        b = min(a + 1, m - 1)
        za = _sample(z, hq, k, off, n, ia, ja, ib, jb, a)
        zb = _sample(z, hq, k, off, n, ia, ja, ib, jb, b)
        sl = za - _sample(z, hq, k, off, n, ia, ja, ib, jb, a - 1)
        sr = _sample(z, hq, k, off, n, ia, ja, ib, jb, b + 1) - zb
        x = 0.5 * (a + b)
        if sl != sr:
            x = (zb - za + sl * a - sr * b) / (sl - sr)
        x = min(max(x, float(a)), float(b))
        out_kind[k] = BREAK_KINK
        out_t[k] = x / m


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
def _perimeter(k, t):
    if k == 0:
        return t
    if k == 1:
        return 1.0 + t
    if k == 2:
        return 3.0 - t
    return 4.0 - t


@njit(cache=True, error_model="numpy")
def _boundary_point(X, Y, dx, dy):
    """(k, t) of the cell side nearest to the boundary point (X, Y)."""
    db = abs(Y)
    dr = abs(dx - X)
    dt = abs(dy - Y)
    dl = abs(X)
    m = min(min(db, dr), min(dt, dl))
    if m == db:
        return 0, min(max(X / dx, 0.0), 1.0)
    if m == dr:
        return 1, min(max(Y / dy, 0.0), 1.0)
    if m == dt:
        return 2, min(max(X / dx, 0.0), 1.0)
    return 3, min(max(Y / dy, 0.0), 1.0)


@njit(cache=True, error_model="numpy")
def _find(sorted_ids, key):
    c = np.searchsorted(sorted_ids, key)
    if c < sorted_ids.shape[0] and sorted_ids[c] == key:
        return c
    return -1


@njit(cache=True, error_model="numpy")
def _far_crossing(ecell_ids, out_nb, out_bk, out_pts, corner, ci, cj, k, ri, rj, px, py, lever, nx, ny, dx, dy):
    """Walk the trace from cell (ci, cj) out through its break on edge k to the first
    crossing at least ``lever`` from (px, py).

    Returns (found, qx, qy, i, j, k_out): the crossing in the cell-local coordinates of cell
    (ri, rj), the cell it closes and the edge through which the trace leaves that cell. The
    walk stops (not found) at a cell that is not a plain two-break cell or holds a corner.
    """
    cur_i, cur_j = ci, cj
    for _ in range(MAX_WALK):
        ni, nj = cur_i, cur_j
        if k == 0:
            nj -= 1
        elif k == 1:
            ni += 1
        elif k == 2:
            nj += 1
        else:
            ni -= 1
        if ni < 0 or nj < 0 or ni > nx - 2 or nj > ny - 2:
            break
        nc = _find(ecell_ids, ni * (ny - 1) + nj)
        if nc < 0 or out_nb[nc] != 2 or corner[nc]:
            break
        shared = (k + 2) % 4
        if out_bk[nc, 0] == shared:
            other = 1
        elif out_bk[nc, 1] == shared:
            other = 0
        else:
            break
        qx = out_pts[nc, 2 * other, 0] + (ni - ri) * dx
        qy = out_pts[nc, 2 * other, 1] + (nj - rj) * dy
        k = out_bk[nc, other]
        if math.hypot(qx - px, qy - py) >= lever:
            return True, qx, qy, ni, nj, k
        cur_i, cur_j = ni, nj
    return False, 0.0, 0.0, 0, 0, 0


@njit(cache=True, error_model="numpy")
def _line_gap(ax, ay, bx, by, px, py):
    """Distance of P from the line through A and B."""
    L = math.hypot(bx - ax, by - ay)
    return abs((bx - ax) * (py - ay) - (by - ay) * (px - ax)) / L


@njit(cache=True, error_model="numpy")
def cell_geometry(ecell_ids, slots, brk_kind, brk_t, nx, ny, dx, dy, straight_tol, out_nb, out_bk, out_bt, out_pts,
                  out_arc):
    """Wall/edge trace of every e-cell with exactly two boundary breaks.

    ``out_nb`` (C,) number of breaks on the cell's boundary that a trace may join (its jumps,
    or its kinks where it has no jump); for two: ``out_bk``/``out_bt``
    (C, 2) their local edges and parameters and ``out_pts`` (C, 3, 2) the trace P1, M, P2 in
    cell-local metric coordinates, ``out_arc`` (C, 3) the trace's circle (centre x, y and
    radius; radius 0 for a polyline P1-M-P2). A smooth wall is the arc through P1 and P2
    with the mean sagitta of the circles through them and the crossing beyond each (found
    by walking the trace at least ``MIN_LEVER`` grid intervals out). A wall corner is
    taken where the traces on both sides are straight (the next crossing out lies within
    ``straight_tol`` of their line), turn by more than ``CORNER_TURN`` and meet inside the
    cell: the trace is then the polyline through that meeting point.
    """
    C = ecell_ids.shape[0]
    for c in range(C):
        # the trace joins two breaks: two jumps (a wall) if there are exactly two, else two
        # kinks (a sharp edge) when there are no jumps; any other count is no single trace
        nj = 0
        nk = 0
        for k in range(4):
            sl = slots[c, k]
            if sl >= 0:
                if brk_kind[sl] == BREAK_JUMP:
                    nj += 1
                elif brk_kind[sl] == BREAK_KINK:
                    nk += 1
        want = BREAK_JUMP if nj > 0 else BREAK_KINK
        nb = 0
        for k in range(4):
            sl = slots[c, k]
            if sl >= 0 and brk_kind[sl] == want:
                if nb < 2:
                    out_bk[c, nb] = k
                    out_bt[c, nb] = brk_t[sl]
                    X, Y = _edge_xy(k, brk_t[sl], dx, dy)
                    out_pts[c, 2 * nb, 0] = X
                    out_pts[c, 2 * nb, 1] = Y
                nb += 1
        out_nb[c] = nb
    corner = np.zeros(C, dtype=np.bool_)
    for c in range(C):  # pass 1: corners (straight traces on both sides meeting in the cell)
        if out_nb[c] == 2:
            corner[c] = _trace(c, ecell_ids, out_nb, out_bk, out_pts, out_arc, corner, nx, ny, dx, dy, straight_tol, True)
    for c in range(C):  # pass 2: arcs, from crossings not beyond a corner
        if out_nb[c] == 2 and not corner[c]:
            _trace(c, ecell_ids, out_nb, out_bk, out_pts, out_arc, corner, nx, ny, dx, dy, straight_tol, False)


@njit(cache=True, error_model="numpy")
def _trace(c, ecell_ids, out_nb, out_bk, out_pts, out_arc, corner, nx, ny, dx, dy, straight_tol, corners):
    """Corner pass (``corners=True``: set M at the corner, return whether there is one) or
    arc pass (set M and the circle of a smooth trace)."""
    ci = ecell_ids[c] // (ny - 1)
    cj = ecell_ids[c] - ci * (ny - 1)
    p1x = out_pts[c, 0, 0]
    p1y = out_pts[c, 0, 1]
    p2x = out_pts[c, 2, 0]
    p2y = out_pts[c, 2, 1]
    mx = 0.5 * (p1x + p2x)
    my = 0.5 * (p1y + p2y)
    L = math.hypot(p2x - p1x, p2y - p1y)
    if corners:
        out_pts[c, 1, 0] = mx
        out_pts[c, 1, 1] = my
    if L <= 1e-12 * (dx + dy):
        return False
    wx = (p2x - p1x) / L
    wy = (p2y - p1y) / L
    lever = MIN_LEVER * min(dx, dy)
    qx = np.zeros(2)
    qy = np.zeros(2)
    has = np.zeros(2, dtype=np.bool_)
    straight = np.zeros(2, dtype=np.bool_)
    for b in range(2):
        px_ = p1x if b == 0 else p2x
        py_ = p1y if b == 0 else p2y
        found, qx[b], qy[b], qi, qj, qk = _far_crossing(ecell_ids, out_nb, out_bk, out_pts, corner, ci, cj,
                                                         out_bk[c, b], ci, cj, px_, py_, lever, nx, ny, dx, dy)
        has[b] = found
        if found and corners:
            f2, rx, ry, _, _, _ = _far_crossing(ecell_ids, out_nb, out_bk, out_pts, corner, qi, qj, qk, ci, cj,
                                                qx[b], qy[b], lever, nx, ny, dx, dy)
            straight[b] = f2 and _line_gap(qx[b], qy[b], px_, py_, rx, ry) <= straight_tol
    if corners:
        if not (has[0] and has[1] and straight[0] and straight[1]):
            return False
        d1x = p1x - qx[0]
        d1y = p1y - qy[0]
        d2x = qx[1] - p2x
        d2y = qy[1] - p2y
        cross = d1x * d2y - d1y * d2x
        turn = math.atan2(abs(cross), d1x * d2x + d1y * d2y)
        if turn <= CORNER_TURN or cross == 0.0:
            return False  # no corner, or the two traces run back along one line (trj8)
        a = ((p2x - p1x) * d2y - (p2y - p1y) * d2x) / cross
        cx = p1x + a * d1x
        cy = p1y + a * d1y
        slack = 1e-9 * (dx + dy)
        if not (-slack <= cx <= dx + slack and -slack <= cy <= dy + slack):
            return False
        out_pts[c, 1, 0] = min(max(cx, 0.0), dx)
        out_pts[c, 1, 1] = min(max(cy, 0.0), dy)
        return True
    # smooth wall: the arc through P1 and P2 whose sagitta is the mean of those of the
    # circles through Q, P1 and P2 on either side
    sag = 0.0
    cnt = 0
    for b in range(2):
        if not has[b]:
            continue
        ok, sg = _arc_sagitta(qx[b], qy[b], p1x, p1y, p2x, p2y)
        if ok:
            sag += sg
            cnt += 1
    if cnt == 0:
        return False
    sag = min(max(sag / cnt, -0.5 * L), 0.5 * L)
    if abs(sag) <= 1e-9 * L:
        return False
    out_pts[c, 1, 0] = mx - sag * wy
    out_pts[c, 1, 1] = my + sag * wx
    # circle through P1, M, P2: centre on the chord's bisector, (L/2)^2 = sag*(2*rho - sag)
    rho = (0.25 * L * L + sag * sag) / (2.0 * abs(sag))
    off = rho - abs(sag)  # centre's distance from the chord, on the side away from M
    sgn = 1.0 if sag > 0 else -1.0
    out_arc[c, 0] = mx + sgn * off * wy
    out_arc[c, 1] = my - sgn * off * wx
    out_arc[c, 2] = rho
    return False


@njit(cache=True, error_model="numpy")
def _arc_sagitta(ax, ay, p1x, p1y, p2x, p2y):
    """Signed sagitta (along the left normal of P1->P2) of the minor arc P1-P2 of the circle
    through A, P1, P2; (False, 0) when the three are collinear."""
    d = 2.0 * (ax * (p1y - p2y) + p1x * (p2y - ay) + p2x * (ay - p1y))
    L = math.hypot(p2x - p1x, p2y - p1y)
    scale = max(math.hypot(ax - p1x, ay - p1y), L)
    if abs(d) <= 1e-12 * scale * scale:
        return True, 0.0
    a2 = ax * ax + ay * ay
    b2 = p1x * p1x + p1y * p1y
    c2 = p2x * p2x + p2y * p2y
    ux = (a2 * (p1y - p2y) + b2 * (p2y - ay) + c2 * (ay - p1y)) / d
    uy = (a2 * (p2x - p1x) + b2 * (ax - p2x) + c2 * (p1x - ax)) / d
    rho = math.hypot(p1x - ux, p1y - uy)
    mx = 0.5 * (p1x + p2x)
    my = 0.5 * (p1y + p2y)
    vx = mx - ux
    vy = my - uy
    dist = math.hypot(vx, vy)
    if dist <= 1e-12 * rho:
        return False, 0.0
    ex = ux + rho * vx / dist - mx
    ey = uy + rho * vy / dist - my
    # left normal of P1->P2 is (-wy, wx)
    return True, (-ex * (p2y - p1y) + ey * (p2x - p1x)) / L


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


@njit(cache=True, error_model="numpy")
def _in_region_a(X, Y, p1x, p1y, mx, my, p2x, p2y, s1, s2, dx, dy):
    """Point (X, Y) inside the polygon P1 -> corners CCW from s1 to s2 -> P2 -> M."""
    span = (s2 - s1) % 4.0
    inside = False
    ax = mx  # start from M (the last vertex)
    ay = my
    for idx in range(7):
        if idx == 0:
            bx = p1x
            by = p1y
        elif idx <= 4:
            kk = math.floor(s1) + idx
            if kk - s1 >= span or kk - s1 <= 0.0:
                continue
            cc = int(kk) % 4
            bx = dx if (cc == 1 or cc == 2) else 0.0
            by = dy if (cc == 2 or cc == 3) else 0.0
        elif idx == 5:
            bx = p2x
            by = p2y
        else:
            bx = mx
            by = my
        if (ay > Y) != (by > Y):
            xint = ax + (Y - ay) * (bx - ax) / (by - ay)
            if X < xint:
                inside = not inside
        ax = bx
        ay = by
    return inside


@njit(cache=True, error_model="numpy")
def _region_a(X, Y, P, arc, s1, s2, dx, dy):
    """Side of the trace holding (X, Y): True for the region whose boundary arc runs CCW
    from P1 (perimeter s1) to P2 (s2)."""
    if arc[2] <= 0.0:
        return _in_region_a(X, Y, P[0, 0], P[0, 1], P[1, 0], P[1, 1], P[2, 0], P[2, 1], s1, s2, dx, dy)
    # circular trace: split by the chord, then move the circular segment between chord
    # and arc (on M's side of the chord, inside the circle) to the other side
    mx = 0.5 * (P[0, 0] + P[2, 0])
    my = 0.5 * (P[0, 1] + P[2, 1])
    a = _in_region_a(X, Y, P[0, 0], P[0, 1], mx, my, P[2, 0], P[2, 1], s1, s2, dx, dy)
    cx = P[2, 0] - P[0, 0]
    cy = P[2, 1] - P[0, 1]
    side_p = cx * (Y - P[0, 1]) - cy * (X - P[0, 0])
    side_m = cx * (P[1, 1] - P[0, 1]) - cy * (P[1, 0] - P[0, 0])
    if side_p * side_m > 0.0 and math.hypot(X - arc[0], Y - arc[1]) <= arc[2]:
        # in the segment: on the side of the arc away from M's side of the chord
        m_in_a = _in_region_a(P[1, 0], P[1, 1], P[0, 0], P[0, 1], mx, my, P[2, 0], P[2, 1], s1, s2, dx, dy)
        return not m_in_a
    return a


@njit(cache=True, error_model="numpy")
def _split(z, i, j, u, v, c, slots, edge_ids, offsets, hq, brk_kind, brk_t, bk, bt, pts, arc, dx, dy):
    """Height on the side of the cell's trace that holds the point, from that side's data.

    The line through the point parallel to the trace's chord meets the cell boundary at A
    and B; their boundary hq (taken from the point's side; a hit beyond the side's arc
    is pulled back to the arc's end at the break) are blended linearly along the line.
    """
    X = u * dx
    Y = v * dy
    k1 = bk[c, 0]
    k2 = bk[c, 1]
    t1 = bt[c, 0]
    t2 = bt[c, 1]
    s1 = _perimeter(k1, t1)
    s2 = _perimeter(k2, t2)
    P = pts[c]
    # the region test counts crossings of edges above and to the right of the point, so a
    # point on the cell's top or right side would lie outside both regions: test it a hair inside
    if _region_a(min(X, dx * (1.0 - 1e-12)), min(Y, dy * (1.0 - 1e-12)), P, arc[c], s1, s2, dx, dy):
        sa, ka, ta, sb, kb, tb_ = s1, k1, t1, s2, k2, t2
    else:
        sa, ka, ta, sb, kb, tb_ = s2, k2, t2, s1, k1, t1
    span = (sb - sa) % 4.0
    wx = P[2, 0] - P[0, 0]
    wy = P[2, 1] - P[0, 1]
    L = math.hypot(wx, wy)
    wx /= L
    wy /= L
    lo = -1e300
    hi = 1e300
    if abs(wx) > 1e-15:
        l1 = -X / wx
        l2 = (dx - X) / wx
        lo = max(lo, min(l1, l2))
        hi = min(hi, max(l1, l2))
    if abs(wy) > 1e-15:
        l1 = -Y / wy
        l2 = (dy - Y) / wy
        lo = max(lo, min(l1, l2))
        hi = min(hi, max(l1, l2))
    va, da = _hit(z, i, j, X, Y, lo, wx, wy, c, sa, ka, ta, sb, kb, tb_, span, slots, edge_ids, offsets, hq,
                  brk_kind, brk_t, dx, dy)
    vb, db = _hit(z, i, j, X, Y, hi, wx, wy, c, sa, ka, ta, sb, kb, tb_, span, slots, edge_ids, offsets, hq,
                  brk_kind, brk_t, dx, dy)
    if da + db <= 0.0:
        return va
    return (va * db + vb * da) / (da + db)


@njit(cache=True, error_model="numpy")
def _hit(z, i, j, X, Y, lam, wx, wy, c, sa, ka, ta, sb, kb, tb_, span, slots, edge_ids, offsets, hq, brk_kind, brk_t, dx, dy):
    """Boundary height and distance of the hit ``P + lam*w``, kept on the arc [sa, sb]."""
    k, t = _boundary_point(X + lam * wx, Y + lam * wy, dx, dy)
    s = _perimeter(k, t)
    if (s - sa) % 4.0 <= span:
        return (_edge_value(z, i, j, k, t, 0, slots[c, k], edge_ids, offsets, hq, brk_kind, brk_t, dx, dy), abs(lam))
    if (sa - s) % 4.0 <= (s - sb) % 4.0:  # pull back to the arc's start; the arc runs CCW from it
        k, t = ka, ta
        sd = 1 if (k == 0 or k == 1) else -1
    else:  # to the arc's end; the arc lies CW from it
        k, t = kb, tb_
        sd = -1 if (k == 0 or k == 1) else 1
    ex, ey = _edge_xy(k, t, dx, dy)
    return (_edge_value(z, i, j, k, t, sd, slots[c, k], edge_ids, offsets, hq, brk_kind, brk_t, dx, dy),
            math.hypot(ex - X, ey - Y))


@njit(cache=True, error_model="numpy", parallel=True)
def ez_kernel(z, x0, y0, dx, dy, cs, sn, ox, oy, xs, ys, edge_ids, offsets, hq, brk_kind, brk_t,
              ecell_ids, slots, nb, bk, bt, pts, arc, bub, out):
    """EZ hq at every query point; NaN outside e-cells (the caller uses the base); ``bub``:
    each e-cell's bubble height (:func:`_coons`)."""
    nx, ny = z.shape
    for p in prange(xs.shape[0]):
        i, j, u, v = _locate(xs[p], ys[p], x0, y0, dx, dy, cs, sn, ox, oy, nx, ny)
        if i < 0:
            out[p] = np.nan
            continue
        c = _find(ecell_ids, i * (ny - 1) + j)
        if c < 0 or math.isnan(z[i, j]) or math.isnan(z[i + 1, j]) or math.isnan(z[i, j + 1]) or math.isnan(z[i + 1, j + 1]):
            out[p] = np.nan
            continue
        if nb[c] == 2 and (pts[c, 0, 0] != pts[c, 2, 0] or pts[c, 0, 1] != pts[c, 2, 1]):
            out[p] = _split(z, i, j, u, v, c, slots, edge_ids, offsets, hq, brk_kind, brk_t, bk, bt, pts, arc, dx, dy)
        else:
            out[p] = _coons(z, i, j, u, v, c, slots, edge_ids, offsets, hq, brk_kind, brk_t, dx, dy, nb[c] > 0, bub[c])


#: :func:`ez_kernel` on one thread: for small batches (a cell patch's few points), where
#: waking the thread pool costs more than the points themselves
ez_kernel_serial = njit(cache=True, error_model="numpy")(ez_kernel.py_func)


@njit(cache=True, error_model="numpy", parallel=True)
def patch_kernel(zs, x0s, y0s, dx, dy, cs, sn, ox, oy, xs, ys, ks, edge_ids, offsets, codes, lo, step, brk_kind,
                 brk_t, ecell_ids, slots, nb, bk, bt, pts, arc, nowin, out):
    """:func:`ez_kernel` over a stack of same-level cell patches: point ``p`` lies in patch
    ``ks[p]``, whose sub-grid is ``zs[k]`` at ``(x0s[k], y0s[k])`` and whose per-edge and
    per-cell tables are row ``k`` of the stacked arrays (ids and slots are shared: every
    patch of a level has every sub-edge; ``offsets[k]`` are patch k's, its sub-edges thinned
    to their own counts; ``nowin``: -1 per sub-edge, patches store no windows)."""
    for p in prange(xs.shape[0]):
        k = ks[p]
        z = zs[k]
        nx, ny = z.shape
        i, j, u, v = _locate(xs[p], ys[p], x0s[k], y0s[k], dx, dy, cs, sn, ox, oy, nx, ny)
        if i < 0:
            out[p] = np.nan
            continue
        c = _find(ecell_ids, i * (ny - 1) + j)
        if c < 0 or math.isnan(z[i, j]) or math.isnan(z[i + 1, j]) or math.isnan(z[i, j + 1]) or math.isnan(z[i + 1, j + 1]):
            out[p] = np.nan
            continue
        off = offsets[k]
        hq = (codes[k], lo[k], step[k], off[:-1], nowin)
        if nb[k, c] == 2 and (pts[k, c, 0, 0] != pts[k, c, 2, 0] or pts[k, c, 0, 1] != pts[k, c, 2, 1]):
            out[p] = _split(z, i, j, u, v, c, slots, edge_ids, off, hq, brk_kind[k], brk_t[k], bk[k], bt[k], pts[k],
                            arc[k], dx, dy)
        else:
            out[p] = _coons(z, i, j, u, v, c, slots, edge_ids, off, hq, brk_kind[k], brk_t[k], dx, dy, nb[k, c] > 0,
                            0.0)


#: :func:`patch_kernel` on one thread, for small batches
patch_kernel_serial = njit(cache=True, error_model="numpy")(patch_kernel.py_func)
