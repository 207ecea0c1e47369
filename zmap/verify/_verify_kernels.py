"""numba kernels of :mod:`zmap.verify`: per-ray history queries and collision scans.

Only ``@njit(cache=True)`` code on flat arrays; validation lives in the public modules.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..sim.history._kernels import treap_top_at

__all__ = ["treap_top_at", "treap_first_below", "holder_hits", "treap_disk_above"]


@njit(cache=True)
def treap_first_below(node_off, root_off, root_hi, tz, ts, tk, rays, level, floor, out,
                      stack_n, stack_lo, stack_hi, cand):
    """First stage at which the top of each ray in ``rays`` went below ``level[q]``.

    A ray's top never rises (cutting only removes material), and it changes only at the
    creation stages of its nodes; so the answer is the first of those stages (0 included)
    whose top is below the level, found by bisection over them. An empty ray counts as
    ``floor[q]`` (the stock's bottom). ``out[q]`` = -1 where the top never went below.
    """
    for q in range(rays.shape[0]):
        r = rays[q]
        a = node_off[r]
        b = node_off[r + 1]
        m = 0
        cand[m] = 0
        m += 1
        for e in range(a, b):
            cand[m] = ts[e]
            m += 1
        c = np.sort(cand[:m])
        # unique in place
        u = 0
        for e in range(m):
            if e == 0 or c[e] != c[u - 1]:
                c[u] = c[e]
                u += 1
        lv = level[q]
        top = treap_top_at(node_off, root_off, root_hi, tz, ts, tk, r, c[u - 1], stack_n, stack_lo, stack_hi)
        if top != top:
            top = floor[q]
        if not top < lv:
            out[q] = -1
            continue
        lo = 0
        hi = u - 1  # c[hi] is below
        while lo < hi:
            mid = (lo + hi) // 2
            t = treap_top_at(node_off, root_off, root_hi, tz, ts, tk, r, c[mid], stack_n, stack_lo, stack_hi)
            if t != t:
                t = floor[q]
            if t < lv:
                hi = mid
            else:
                lo = mid + 1
        out[q] = c[lo]


@njit(cache=True)
def holder_hits(xyz, top_max, x0, y0, pitch, nx, ny, radius, lift, out):
    """For each tip position, the largest ``top_max`` (mm) over the rays within ``radius``
    of the axis minus the height ``tip z + lift`` (> 0: material above that height)."""
    n = xyz.shape[0]
    rr = radius * radius
    for p in range(n):
        cx = xyz[p, 0]
        cy = xyz[p, 1]
        zb = xyz[p, 2] + lift
        i0 = max(0, int(np.ceil((cx - radius - x0) / pitch)))
        i1 = min(nx - 1, int(np.floor((cx + radius - x0) / pitch)))
        j0 = max(0, int(np.ceil((cy - radius - y0) / pitch)))
        j1 = min(ny - 1, int(np.floor((cy + radius - y0) / pitch)))
        best = -np.inf
        for i in range(i0, i1 + 1):
            dx = x0 + i * pitch - cx
            for j in range(j0, j1 + 1):
                dy = y0 + j * pitch - cy
                if dx * dx + dy * dy <= rr:
                    t = top_max[i * ny + j]
                    if t == t and t - zb > best:
                        best = t - zb
        out[p] = best


@njit(cache=True)
def treap_disk_above(node_off, root_off, root_hi, tz, ts, tk, xyz, stages, x0, y0, pitch, nx, ny,
                     radius, lift, out, stack_n, stack_lo, stack_hi):
    """Per position p: the largest (top at ``stages[p]`` - (tip z + lift)) over the rays within
    ``radius`` of the tool axis (mm; -inf where no ray has material)."""
    n = xyz.shape[0]
    rr = radius * radius
    for p in range(n):
        cx = xyz[p, 0]
        cy = xyz[p, 1]
        zb = xyz[p, 2] + lift
        i0 = max(0, int(np.ceil((cx - radius - x0) / pitch)))
        i1 = min(nx - 1, int(np.floor((cx + radius - x0) / pitch)))
        j0 = max(0, int(np.ceil((cy - radius - y0) / pitch)))
        j1 = min(ny - 1, int(np.floor((cy + radius - y0) / pitch)))
        best = -np.inf
        for i in range(i0, i1 + 1):
            dx = x0 + i * pitch - cx
            for j in range(j0, j1 + 1):
                dy = y0 + j * pitch - cy
                if dx * dx + dy * dy <= rr:
                    t = treap_top_at(node_off, root_off, root_hi, tz, ts, tk, i * ny + j, stages[p],
                                     stack_n, stack_lo, stack_hi)
                    if t == t and t - zb > best:
                        best = t - zb
        out[p] = best
