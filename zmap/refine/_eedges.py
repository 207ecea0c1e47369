"""The e-edges of an e-map: the grid's edges and the cells around the e-edges, the e-points an
edge holds, the thresholds of its breaks, and its thinning (:func:`decimate`: a smooth edge
to the fewest knots, a wall edge to a window around its jump) with the windows' flags and
storage (:func:`split_forced`, :func:`virtual_offsets`, :func:`pack_windows`).

Grid edges and ids (as :mod:`zmap.refine.ez` states them): the x-edge ``(i, j)-(i+1, j)`` has
id ``i*ny + j``, the y-edge ``(i, j)-(i, j+1)`` has id ``(nx-1)*ny + i*(ny-1) + j``.
"""

from __future__ import annotations

import math

import numpy as np

from ._ecodec import QUANTUM_SHARE, encode_heights

__all__ = ["BREAK_RATIO", "KINK_SHIFT", "THIN_ROUNDS", "WINDOW_HALF", "_n_points", "break_thresholds",
           "cells_around", "decimate", "edge_count", "pack_windows", "split_forced", "unpack_windows",
           "virtual_offsets"]

#: A windowed edge's break may move this share of an e-map interval from the full
#: sequence's (a kink placed from coded heights: 0.05 of 0.01 mm is 5e-4 mm).
KINK_SHIFT = 0.05
#: Tries at more knots for a thinned edge whose knots show a break (:func:`decimate`).
THIN_ROUNDS = 4
#: A windowed wall edge keeps its full samples from this many before the jump's interval
#: to this many after it (the jump and the slopes its two sides are extended by).
WINDOW_HALF = 1
#: A jump or kink must stand out this many times from its neighbours to count as a break.
BREAK_RATIO = 4.0


def edge_count(nx: int, ny: int) -> int:
    """Number of grid edges of an ``nx`` by ``ny`` grid: ``(nx-1)*ny + nx*(ny-1)``."""
    return (nx - 1) * ny + nx * (ny - 1)


def cells_around(nx: int, ny: int, ids: np.ndarray) -> np.ndarray:
    """Cells next to the grid edges ``ids`` and the ring whose Bezier stencil reaches them.

    Returns a bool ndarray of shape (nx-1, ny-1).
    """
    nxe = (nx - 1) * ny
    is_x = ids < nxe
    a, r = ids[is_x] // ny, ids[is_x] % ny
    yi, yb = (ids[~is_x] - nxe) // (ny - 1), (ids[~is_x] - nxe) % (ny - 1)
    # x-edge (a, r): own cells (a, r), (a, r-1); stencil ring (a+-1, r), (a+-1, r-1)
    # y-edge (yi, yb): own cells (yi, yb), (yi-1, yb); ring (yi, yb+-1), (yi-1, yb+-1)
    ci = np.concatenate([a, a, a + 1, a + 1, a - 1, a - 1, yi, yi - 1, yi, yi - 1, yi, yi - 1])
    cj = np.concatenate([r, r - 1, r, r - 1, r, r - 1, yb, yb, yb + 1, yb + 1, yb - 1, yb - 1])
    ok = (ci >= 0) & (ci <= nx - 2) & (cj >= 0) & (cj <= ny - 2)
    m = np.zeros((nx - 1) * (ny - 1), dtype=bool)
    m[ci[ok] * (ny - 1) + cj[ok]] = True
    return m.reshape(nx - 1, ny - 1)


def _n_points(length: float, interval: float) -> int:
    """Interior points that split ``length`` into pieces no longer than ``interval``."""
    return max(math.ceil(length / interval - 1e-9) - 1, 0)


def break_thresholds(dx: float, dy: float, interval: float, tol: float) -> tuple[float, float]:
    """``(jump_min, kink_min)`` of :func:`zmap.refine._ez_kernels.detect_breaks` for an e-map
    of ``interval`` on a ``dx`` by ``dy`` grid built for ``tol``."""
    n_max = max(_n_points(dx, interval), _n_points(dy, interval)) + 1
    return tol, 4.0 * tol / n_max


def decimate(z: np.ndarray, dx: float, dy: float, interval: float, tol: float, edge_ids: np.ndarray,
             offsets: np.ndarray, heights: np.ndarray, limit: float, *, window: bool = False,
             bare: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Thin each smooth edge to the fewest evenly spaced e-points that interpolate all of its
    points linearly within ``limit``; with ``window``, thin each wall edge outside a window
    around its jump.

    The new points (``d - 1`` of them at ``t = k / d``, ``d`` from 2, 3, 4, 5, 6, 8, ...) are
    read off the edge's full sequence, linear between samples, as the cells evaluate it; so
    the thinned boundary curve is within ``limit`` of the full one everywhere (their
    difference is linear between the union of both sets of knots, zero at the new knots and
    checked at the full ones). An edge keeps all its points where its sequence has a break
    (a wall or a sharp edge, :func:`zmap.refine._ez_kernels.detect_breaks`), where the
    thinned sequence would show one, or where a height is missing: its cells split the same
    way (no break either way).

    A smooth edge whose thinned sequence shows a break gets more knots (the next counts,
    :data:`THIN_ROUNDS` tries) before it is kept whole.

    ``window``: an edge with a break (a wall's jump or a sharp edge's kink) keeps the full
    samples from :data:`WINDOW_HALF` before the break's interval to as many after it, and
    each side of them is thinned the same way to its own fewest knots (spans of 1, 2, 3, 4,
    5, 6, 8, ... intervals). The kernels read it as its full sequence, a sample outside the window
    linear between the knots of its side (:func:`zmap.refine._edge_kernels._sample`), so the
    jump, the samples either side of it and the break found are those of the full sequence
    (checked: an edge whose windowed sequence shows another break keeps all its points).

    ``bare``: a smooth edge whose corners alone interpolate its points within ``limit``
    keeps no e-point (a cell patch's sub-edges: linear between its sub-grid nodes);
    otherwise every edge keeps at least one.

    Parameters
    ----------
    z : ndarray of shape (nx, ny)
        Grid heights (the edges' corners).
    dx, dy, interval, tol : float
        Grid steps, e-map interval and tolerance (the break thresholds).
    edge_ids, offsets : ndarray of int64
        The e-edges and their CSR offsets (interior points at ``t = q / (n + 1)``).
    heights : ndarray of shape (P,), float64
        E-point heights (NaN = none).
    limit : float
        Largest difference allowed at a full point, mm.

    Returns
    -------
    offsets, heights : ndarray
        The thinned CSR offsets and heights as stored (the same edges, each still with at
        least one point unless ``bare``).
    win : ndarray of shape (E,), int64
        Packed window of each windowed edge (:func:`zmap.refine._ez_kernels.pack_window`),
        -1 for the others.
    """
    from . import _ez_kernels as _k

    E = edge_ids.shape[0]
    nowin = np.full(E, -1, dtype=np.int64)
    if E == 0:
        return offsets, heights, nowin
    heights = np.ascontiguousarray(heights, dtype=np.float64)
    n = np.diff(offsets)
    d = np.empty(E, dtype=np.int64)
    _k.decimate_counts(z, edge_ids, offsets, heights, float(limit), 1 if bare else 2, d)
    jump_min, kink_min = break_thresholds(dx, dy, interval, tol)

    def breaks(off, h, win, forced):
        kind = np.zeros(E, dtype=np.int8)
        t = np.zeros(E, dtype=np.float64)
        codes, lo, step = encode_heights(off, h, QUANTUM_SHARE * tol)
        vo = virtual_offsets(off, n, win)
        _k.detect_breaks(z, edge_ids, vo, (codes, lo, step, np.ascontiguousarray(off[:-1]), win), forced, jump_min,
                         kink_min, BREAK_RATIO, kind, t)
        return kind, t

    def thinned(dd, win):
        off = np.zeros(E + 1, dtype=np.int64)
        size = dd - 1
        w = np.flatnonzero(win >= 0)
        size[w] = [_k.window_size(int(win[k]), int(n[k])) for k in w]
        np.cumsum(size, out=off[1:])
        out = np.empty(int(off[-1]))
        _k.resample(z, edge_ids, offsets, heights, np.where(win >= 0, -1, dd - 1), off, out)
        _k.window_resample(z, edge_ids, offsets, heights, win, off, out)
        return off, out

    kind0, t0 = breaks(offsets, heights, nowin, np.zeros(E, dtype=np.int8))
    full = kind0 != 0
    # a window's break is forced: the full sequence's kind, placed inside the window
    flags = np.where(kind0 == 2, _k.WIN_FORCED | _k.WIN_KINK, _k.WIN_FORCED).astype(np.int64)
    forced = lambda w: np.where(w >= 0, w | flags, w)
    d[full] = n[full] + 1
    win = nowin.copy()
    if window:
        sel = np.flatnonzero(kind0 != 0).astype(np.int64)
        _k.window_counts(z, edge_ids, offsets, heights, t0, sel, WINDOW_HALF, float(limit), win)
        # a window that stores no fewer codes than the full edge is not one
        small = np.array([_k.window_size(int(win[k]), int(n[k])) < n[k] if win[k] >= 0 else False for k in sel],
                         dtype=bool)
        win[sel[~small]] = -1
    if not np.any((d < n + 1) | (win >= 0)):
        return offsets, heights, nowin
    off, h = thinned(d, win)
    w_limit = np.full(E, float(limit))
    for _ in range(THIN_ROUNDS + 1):
        kind1, t1 = breaks(off, h, win, np.where(win >= 0, kind0, 0).astype(np.int8))
        # a kink's place moves with the codes' quantum (the window's range is not the edge's):
        # up to KINK_SHIFT samples is the same break
        bad_w = (win >= 0) & ((kind1 != kind0) | (np.abs(t1 - t0) * (n + 1) > KINK_SHIFT))
        bad_u = (kind1 != 0) & (d < n + 1) & (win < 0)
        if not (bad_w.any() or bad_u.any()):
            break
        # a window whose knots move the break (a kink's second differences against those at
        # the knots) gets knots at a quarter of the limit, then keeps its edge whole; a
        # smooth edge whose knots show a break gets more knots (the whole edge after
        # THIN_ROUNDS tries)
        retry = bad_w & (w_limit > limit / 20.0) & (_ < THIN_ROUNDS - 1)
        if retry.any():
            w_limit[retry] /= 4.0
            for lim in np.unique(w_limit[retry]):
                sel = np.flatnonzero(retry & (w_limit == lim)).astype(np.int64)
                _k.window_counts(z, edge_ids, offsets, heights, t0, sel, WINDOW_HALF, float(lim), win)
            bad_w &= ~retry
            small = np.array([_k.window_size(int(win[k]), int(n[k])) < n[k] if win[k] >= 0 else False
                              for k in np.flatnonzero(retry)], dtype=bool)
            win[np.flatnonzero(retry)[~small]] = -1
            d[np.flatnonzero(retry)[~small]] = n[np.flatnonzero(retry)[~small]] + 1
        win[bad_w] = -1
        d[bad_w] = n[bad_w] + 1
        d[bad_u] = np.minimum(np.maximum(d[bad_u] + 1, (d[bad_u] * 5) // 4), n[bad_u] + 1)
        if _ == THIN_ROUNDS - 1:
            d[bad_u] = n[bad_u] + 1
        off, h = thinned(d, win)
    return off, h, forced(win)


def split_forced(win: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(win, forced)`` of windows that carry the flag bits :func:`decimate` returns them
    with: the windows without them, and each edge's forced break (see :class:`EZMap`)."""
    from . import _ez_kernels as _k

    win = np.asarray(win, dtype=np.int64)
    flag = (win >= 0) & ((win & _k.WIN_FORCED) != 0)
    forced = np.where(flag, np.where((win & _k.WIN_KINK) != 0, 2, 1), 0).astype(np.int8)
    return np.where(win >= 0, win & ~np.int64(_k.WIN_FORCED | _k.WIN_KINK), win), forced


def virtual_offsets(offsets: np.ndarray, full: np.ndarray | int, win: np.ndarray | None) -> np.ndarray:
    """The offsets the kernels index by: a windowed edge (``win >= 0``) counts its ``full``
    samples (an int or one per edge), the others what they store."""
    if win is None or not np.any(win >= 0):
        return offsets
    cnt = np.diff(offsets)
    w = win >= 0
    cnt[w] = np.broadcast_to(full, cnt.shape)[w]
    vo = np.zeros_like(offsets)
    np.cumsum(cnt, out=vo[1:])
    return vo


def pack_windows(win: np.ndarray, forced: np.ndarray) -> dict[str, np.ndarray]:
    """The windows of an e-map's edges as stored: one bit per e-edge, and per windowed edge
    the first full sample of its break's interval ``b`` and its left knots ``dl - 1`` (uint8
    or uint16); the rest follows from :data:`WINDOW_HALF`, the full count and the stored count.
    Format 5 adds a bit per windowed edge, its forced break a kink (``win_kink``), and
    ``win_forced`` (a bit each) only where some break is not forced (a format-4 map).

    Parameters
    ----------
    win : ndarray of shape (E,), int64
        Packed window of each e-edge (:func:`zmap.refine._ez_kernels.pack_window`, without
        the flag bits), -1 for an edge without one.
    forced : ndarray of shape (E,), int8
        Forced break of each e-edge (1 a jump, 2 a kink, 0 none).

    Returns
    -------
    dict of str to ndarray
        The stored arrays; empty where no edge has a window.
    """
    w = np.flatnonzero(win >= 0)
    if w.size == 0:
        return {}
    ww = win[w]
    a, c, dl = ww & 0x7FFF, (ww >> 16) & 0x7FFF, (ww >> 32) & 0xFFFF
    b = np.where(a > 0, a + WINDOW_HALF, c - 1 - WINDOW_HALF)
    nl = np.maximum(dl - 1, 0)
    dt = np.uint8 if max(int(b.max()), int(nl.max())) < 256 else np.uint16
    is_forced = forced[w] != 0
    out = {"win_bits": np.packbits(win >= 0), "win_b": b.astype(dt), "win_nl": nl.astype(dt),
           "win_kink": np.packbits(forced[w] == 2)}
    if not is_forced.all():
        out["win_forced"] = np.packbits(is_forced)
    return out


def unpack_windows(arrays: dict, edge_ids: np.ndarray, counts: np.ndarray, full: np.ndarray) -> np.ndarray | None:
    """Inverse of :func:`pack_windows` given the stored and full counts per e-edge (format 4,
    without ``win_kink``: no break forced).

    Parameters
    ----------
    arrays : dict of str to ndarray
        An e-map's stored arrays.
    edge_ids, counts, full : ndarray of shape (E,), int64
        The e-edges, the codes each stores and its full samples.

    Returns
    -------
    ndarray of shape (E,), int64, or None
        Packed windows with the flag bits of their forced breaks
        (:data:`zmap.refine._ez_kernels.WIN_FORCED`, ``WIN_KINK``), as
        :class:`zmap.refine._emap.EZMap` takes them; None where the map stores none.

    Raises
    ------
    ValueError
        Where the windows do not fit the counts.
    """
    from . import _ez_kernels as _k

    if "win_bits" not in arrays:
        return None
    E = edge_ids.size
    on = np.flatnonzero(np.unpackbits(np.asarray(arrays["win_bits"], dtype=np.uint8), count=E))
    b = np.asarray(arrays["win_b"]).astype(np.int64)
    nl = np.asarray(arrays["win_nl"]).astype(np.int64)
    if b.shape != on.shape or nl.shape != on.shape:
        raise ValueError(f"e-map arrays: {b.size} window positions for {on.size} windowed edges")
    m = full[on] + 1
    a = np.maximum(b - WINDOW_HALF, 0)
    c = np.minimum(b + 1 + WINDOW_HALF, m)
    dl = np.where(a > 0, nl + 1, 0)
    nr = counts[on] - nl - (np.minimum(c, m - 1) - np.maximum(a, 1) + 1)
    dr = np.where(c < m, nr + 1, 0)
    if np.any(nr < 0) or np.any((c >= m) & (nr != 0)):
        raise ValueError("e-map arrays: a windowed edge's stored count does not fit its window")
    win = np.full(E, -1, dtype=np.int64)
    win[on] = a | (c << 16) | (dl << 32) | (dr << 48)
    if "win_kink" in arrays:
        bits = lambda name: np.unpackbits(np.asarray(arrays[name], dtype=np.uint8), count=on.size).astype(bool)
        forced = bits("win_forced") if "win_forced" in arrays else np.ones(on.size, dtype=bool)
        kink = bits("win_kink")
        win[on] |= np.where(forced, _k.WIN_FORCED, 0) | np.where(forced & kink, _k.WIN_KINK, 0)
    return win
