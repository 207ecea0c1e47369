"""Numba kernels of the e-edges' samples (conventions: :mod:`zmap.refine._ez_kernels`).

An e-edge's sequence is its two grid corners and its e-points between them, stored as 16-bit
codes; a thinned wall edge stores a window of them (:func:`pack_window`). :func:`_sample`
reads any sample of the full sequence from the codes (every evaluation kernel goes through
it), and :func:`detect_breaks` finds each edge's break, the wall or sharp edge a cell is
split along. No validation here: callers own the API.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

__all__ = ["BREAK_JUMP", "BREAK_KINK", "BREAK_NONE", "NAN_CODE", "WINDOW_HALF", "WIN_FORCED", "WIN_KINK",
           "_edge_corners", "_sample", "detect_breaks", "pack_window", "unpack_window", "window_break",
           "window_size"]


BREAK_NONE = 0
BREAK_JUMP = 1
BREAK_KINK = 2
# 16-bit e-point code meaning 'no height' (valid codes are 0..NAN_CODE-1).
NAN_CODE = 65535


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


@njit(cache=True, error_model="numpy")
def window_size(win, n):
    """Codes a windowed edge of ``n`` full samples stores."""
    a, c, dl, dr = unpack_window(win)
    qlo = a if a >= 1 else 1
    return (dl - 1 if dl > 0 else 0) + (min(c, n) - qlo + 1) + (dr - 1 if dr > 0 else 0)


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
