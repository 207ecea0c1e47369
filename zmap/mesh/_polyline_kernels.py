"""Numba kernels of the border polylines of :mod:`zmap.mesh.decimate`'s regions: a side's
nodes refined greedily to the tolerance, afresh or extending what is kept, and the positions
kept on a side (no validation, flat arrays only).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["refine_line", "_side", "_line_side"]


@njit(cache=True)
def refine_line(h, tol, keep):
    """Mark in ``keep`` the nodes of the polyline ``h`` kept so that every node is within
    ``tol`` of the linear interpolation between kept nodes (greedy worst-node insertion)."""
    n = h.shape[0]
    for k in range(n):
        keep[k] = False
    if n == 0:
        return
    keep[0] = True
    keep[n - 1] = True
    stack = np.empty(2 * n + 2, dtype=np.int64)
    sp = 0
    stack[0] = 0
    stack[1] = n - 1
    sp = 2
    while sp > 0:
        b = stack[sp - 1]
        a = stack[sp - 2]
        sp -= 2
        if b - a < 2:
            continue
        ha = h[a]
        hb = h[b]
        inv = 1.0 / (b - a)
        worst = -1.0
        m = -1
        for k in range(a + 1, b):
            e = abs(ha + (hb - ha) * ((k - a) * inv) - h[k])
            if e > worst:
                worst = e
                m = k
        if worst > tol:
            keep[m] = True
            stack[sp] = a
            stack[sp + 1] = m
            stack[sp + 2] = m
            stack[sp + 3] = b
            sp += 4


@njit(cache=True)
def _refine_more_line(h, tol, keep, tmp):
    """Extend ``keep`` (its two ends kept) so that every node of ``h`` is within ``tol`` of
    the polyline through the kept nodes: each span between kept nodes refined greedily."""
    n = h.shape[0]
    keep[0] = True
    keep[n - 1] = True
    a = 0
    for b in range(1, n):
        if not keep[b]:
            continue
        if b - a >= 2:
            refine_line(h[a:b + 1], tol, tmp[:b - a + 1])
            for k in range(a + 1, b):
                if tmp[k - a]:
                    keep[k] = True
        a = b


@njit(cache=True)
def _side(keep, n):
    """Positions 1..n-2 that ``keep`` marks (a region side's border vertices, corners out)."""
    c = 0
    for k in range(1, n - 1):
        if keep[k]:
            c += 1
    out = np.empty(c, dtype=np.int64)
    c = 0
    for k in range(1, n - 1):
        if keep[k]:
            out[c] = k
            c += 1
    return out


@njit(cache=True)
def _line_side(h, tol, keep, tmp, any_dense, all_fresh):
    """The border vertices of one side shared by up to two regions, in ``keep``: every node
    next to a dense region; refined afresh when every region on it is meshed afresh;
    otherwise extended from what the regions already hold (so both keep the same)."""
    n = h.shape[0]
    if any_dense:
        for k in range(n):
            keep[k] = True
    elif all_fresh:
        refine_line(h, tol, keep)
    else:
        _refine_more_line(h, tol, keep, tmp)
