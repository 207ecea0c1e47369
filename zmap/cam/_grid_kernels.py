"""numba kernels of the drop-cutter's discrete phase on a tensor grid of axis positions.

On a grid of axes ``(qx[a], qy[b])`` the discrete CL is a max-plus convolution of the height
samples ``z[i, j]`` (at ``(x0 + i*dx, y0 + j*dy)``, NaN: no surface) with the cutter::

    cl[a, b] = max over samples with |sample - axis| <= R of  z[i, j] - envelope(|sample - axis|)

It is done one lattice column at a time: for the axis row ``qx[a]`` and the column ``i``
(offset ``ex = x0 + i*dx - qx[a]``), every sample ``j`` is a copy of the same kernel
``k(t) = -envelope(hypot(ex, t))`` on ``|t| <= rho = sqrt(R^2 - ex^2)``, shifted to
``y0 + j*dy`` and raised by ``z[i, j]``. The kernel is concave (the envelope is convex and
non-decreasing in ``r``, and ``r`` is convex in ``t``), so two copies cross at most once and
the later one wins on the right: their upper envelope is built with a stack in O(samples)
(as Felzenszwalb & Huttenlocher's distance transform builds its lower envelope of
parabolas) and read at the sorted ``qy`` in one sweep. The cost is
O(rows * columns-in-the-disk * (samples + axes per row)), not O(axes * disk area), and the
result is exactly the brute-force max over the samples (``tests/zmap/cam/test_grid.py``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ..sim._tool_kernels import _envelope

__all__ = ["drop_grid"]


@njit(cache=True)
def _copy(code, R, rc, ex, rho, yc, zc, t):
    """Value at ``t`` of the copy centred at ``yc`` raised by ``zc`` (-inf off its support)."""
    d = t - yc
    if ex * ex + d * d > R * R:  # the disk's test of the pyramid drop, to the last bit
        return -np.inf
    if code == 1:  # the ball: sqrt(R^2 - ex^2 - d^2) - R, one root
        return zc + math.sqrt(max(rho * rho - d * d, 0.0)) - R
    return zc - _envelope(code, R, rc, min(math.hypot(ex, d), R))


@njit(cache=True)
def _copy_in(code, R, rc, ex, rho, yc, zc, t):
    """:func:`_copy` at a ``t`` known to lie on the support (rounding clamped)."""
    d = min(max(t - yc, -rho), rho)
    if code == 1:
        return zc + math.sqrt(max(rho * rho - d * d, 0.0)) - R
    return zc - _envelope(code, R, rc, min(math.hypot(ex, d), R))


@njit(cache=True)
def _cross(code, R, rc, ex, rho, ya, za, yb, zb):
    """The first ``t`` from which the copy at ``yb`` (> ``ya``) is at least the one at ``ya``."""
    lo = yb - rho
    hi = ya + rho
    if lo >= hi:  # supports apart (or touching): b from the start of its support
        return lo
    if code == 1:
        # two semicircles of radius rho: where their upper arcs cross, it is at the upper
        # intersection of the circles, mid + h * (-(zb - za), yb - ya) / D
        sy = yb - ya
        sz = zb - za
        D2 = sy * sy + sz * sz
        q = rho * rho - 0.25 * D2
        if q >= 0.0:
            D = math.sqrt(D2)
            h = math.sqrt(q)
            zi = 0.5 * (za + zb) + h * sy / D
            if zi >= za and zi >= zb:
                return min(max(0.5 * (ya + yb) - h * sz / D, lo), hi)
        # no crossing inside the overlap: one copy is above the other all over it
        m = 0.5 * (lo + hi)
        if _copy_in(code, R, rc, ex, rho, yb, zb, m) >= _copy_in(code, R, rc, ex, rho, ya, za, m):
            return lo
        return hi
    if _copy_in(code, R, rc, ex, rho, yb, zb, lo) >= _copy_in(code, R, rc, ex, rho, ya, za, lo):
        return lo
    if _copy_in(code, R, rc, ex, rho, yb, zb, hi) < _copy_in(code, R, rc, ex, rho, ya, za, hi):
        return hi
    # bull: bisection on the monotone difference (flat ends never get here: their copies
    # differ by a constant, decided at the ends)
    for _ in range(80):
        if hi - lo <= 1e-11 * (1.0 + abs(hi)):
            break
        m = 0.5 * (lo + hi)
        if _copy_in(code, R, rc, ex, rho, yb, zb, m) >= _copy_in(code, R, rc, ex, rho, ya, za, m):
            hi = m
        else:
            lo = m
    return hi
    if code == 1:
        # two semicircles of radius rho: their upper arcs cross at the upper intersection
        # of the circles, (mid) + h * (-(zb - za), yb - ya) / D
        sy = yb - ya
        sz = zb - za
        D = math.hypot(sy, sz)
        h = math.sqrt(max(rho * rho - 0.25 * D * D, 0.0))
        t = 0.5 * (ya + yb) - h * sz / D
        return min(max(t, lo), hi)
    # bull: bisection on the monotone difference (flat ends never get here: their copies
    # differ by a constant, decided at the ends)
    for _ in range(80):
        m = 0.5 * (lo + hi)
        if m <= lo or m >= hi:
            break
        if _copy_in(code, R, rc, ex, rho, yb, zb, m) >= _copy_in(code, R, rc, ex, rho, ya, za, m):
            hi = m
        else:
            lo = m
    return hi


@njit(cache=True)
def _drop_row(z, x0, y0, dx, dy, code, R, rc, qx, qys, out, oi, oj, stk, start):
    """One axis row ``(qx, qys[:])`` (``qys`` ascending): ``out``/``oi``/``oj`` the best
    contact over the samples and its sample (-inf / -1: none)."""
    nx, ny = z.shape
    nq = qys.shape[0]
    for b in range(nq):
        out[b] = -np.inf
        oi[b] = -1
        oj[b] = -1
    if nq == 0:
        return
    i_lo = max(0, math.ceil((qx - R - x0) / dx))
    i_hi = min(nx - 1, math.floor((qx + R - x0) / dx))
    for i in range(i_lo, i_hi + 1):
        ex = x0 + i * dx - qx
        q = R * R - ex * ex
        if q < 0.0:
            continue
        rho = math.sqrt(q)
        j_lo = max(0, math.ceil((qys[0] - rho - y0) / dy))
        j_hi = min(ny - 1, math.floor((qys[nq - 1] + rho - y0) / dy))
        m = 0
        for j in range(j_lo, j_hi + 1):
            zb = z[i, j]
            if math.isnan(zb):
                continue
            yb = y0 + j * dy
            t = -np.inf
            while m > 0:
                ja = stk[m - 1]
                t = _cross(code, R, rc, ex, rho, y0 + ja * dy, z[i, ja], yb, zb)
                if t <= start[m - 1]:
                    m -= 1
                    t = -np.inf
                else:
                    break
            stk[m] = j
            start[m] = t
            m += 1
        if m == 0:
            continue
        k = 0
        for b in range(nq):
            t = qys[b]
            while k + 1 < m and start[k + 1] <= t:
                k += 1
            j = stk[k]
            g = _copy(code, R, rc, ex, rho, y0 + j * dy, z[i, j], t)
            # at a switch between copies (or a support's end) rounding may pick the wrong
            # one of two: read the neighbours too
            eps = 1e-9 * (1.0 + abs(t))
            if g == -np.inf or t - start[k] < eps or (k + 1 < m and start[k + 1] - t < eps):
                for kk in range(max(k - 1, 0), min(k + 2, m)):
                    jj = stk[kk]
                    gg = _copy(code, R, rc, ex, rho, y0 + jj * dy, z[i, jj], t)
                    if gg > g:
                        g = gg
                        j = jj
            if g > out[b]:
                out[b] = g
                oi[b] = i
                oj[b] = j


@njit(cache=True, parallel=True)
def drop_grid(z, x0, y0, dx, dy, code, R, rc, qxs, qys, out, oi, oj):
    """Discrete CL on the tensor grid ``(qxs[a], qys[b])`` (``qys`` ascending): ``out[a, b]``
    = max of ``z[i, j] - envelope(d)`` over the finite samples at distance ``d <= R`` from the
    axis (-inf: none), ``(oi, oj)[a, b]`` its sample (-1: none)."""
    nqx = qxs.shape[0]
    ny = z.shape[1]
    for a in prange(nqx):
        stk = np.empty(ny + 1, dtype=np.int64)
        start = np.empty(ny + 1, dtype=np.float64)
        _drop_row(z, x0, y0, dx, dy, code, R, rc, qxs[a], qys, out[a], oi[a], oj[a], stk, start)
