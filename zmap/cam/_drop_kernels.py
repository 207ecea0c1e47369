"""numba kernels of the drop-cutter (:mod:`zmap.cam.drop`): no validation, flat arrays.

The discrete drop runs over height samples ``z[i, j]`` at ``(x0 + i*dx, y0 + j*dy)`` (NaN: no
surface) with a block-max pyramid: a block of ``B x B`` samples can raise the cutter at most
to ``max(block) - envelope(distance from the axis to the block)``, so blocks are visited
best bound first and the search stops when no bound beats the best contact found.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ..sim._tool_kernels import _envelope

__all__ = ["block_max", "drop_samples", "envelope_many"]


@njit(cache=True, parallel=True)
def block_max(z, B, out):
    """``out[bi, bj]`` = max of the finite ``z`` in block (bi, bj) of B x B samples (-inf: none)."""
    nbx, nby = out.shape
    nx, ny = z.shape
    for bi in prange(nbx):
        for bj in range(nby):
            m = -np.inf
            for i in range(bi * B, min(bi * B + B, nx)):
                for j in range(bj * B, min(bj * B + B, ny)):
                    v = z[i, j]
                    if v == v and v > m:
                        m = v
            out[bi, bj] = m


@njit(cache=True)
def envelope_many(code, radius, corner, r, out):
    for k in range(r.shape[0]):
        out[k] = _envelope(code, radius, corner, r[k])


@njit(cache=True)
def _drop_one(z, zu, x0, y0, dx, dy, bmax, B, code, R, rc, slack, cell, qx, qy, ub, bid, kv, kd, ki, kj, w0, wi, wj):
    band = -np.inf
    nx, ny = z.shape
    nbx, nby = bmax.shape
    best = -np.inf
    bd = np.inf
    bi_ = -1
    bj_ = -1
    for q in range(kv.shape[0]):
        kv[q] = -np.inf
        kd[q] = np.inf
        ki[q] = -1
        kj[q] = -1
    # warm start: the sample nearest the axis
    ic = int(math.floor((qx - x0) / dx + 0.5))
    jc = int(math.floor((qy - y0) / dy + 0.5))
    if 0 <= ic < nx and 0 <= jc < ny:
        v = z[ic, jc]
        d = math.hypot(x0 + ic * dx - qx, y0 + jc * dy - qy)
        if v == v and d <= R:
            best = v - _envelope(code, R, rc, d)
            bd = d
            bi_ = ic
            bj_ = jc
    # a warm start (a sample's contact known already, e.g. from the tensor-grid drop): the
    # blocks that cannot beat it are never opened
    if wi >= 0 and w0 > best:
        best = w0
        bd = math.hypot(x0 + wi * dx - qx, y0 + wj * dy - qy)
        bi_ = wi
        bj_ = wj
    Rs = R + slack
    i_lo = max(0, int(math.ceil((qx - Rs - x0) / dx)))
    i_hi = min(nx - 1, int(math.floor((qx + Rs - x0) / dx)))
    j_lo = max(0, int(math.ceil((qy - Rs - y0) / dy)))
    j_hi = min(ny - 1, int(math.floor((qy + Rs - y0) / dy)))
    if i_lo > i_hi or j_lo > j_hi:
        return best, bi_, bj_, band
    m = 0
    for bi in range(i_lo // B, i_hi // B + 1):
        xa = x0 + bi * B * dx
        xb = x0 + min(bi * B + B - 1, nx - 1) * dx
        ddx = 0.0
        if qx < xa:
            ddx = xa - qx
        elif qx > xb:
            ddx = qx - xb
        for bj in range(j_lo // B, j_hi // B + 1):
            mx = bmax[bi, bj]
            if mx == -np.inf:
                continue
            ya = y0 + bj * B * dy
            yb = y0 + min(bj * B + B - 1, ny - 1) * dy
            ddy = 0.0
            if qy < ya:
                ddy = ya - qy
            elif qy > yb:
                ddy = qy - yb
            dmin = math.sqrt(ddx * ddx + ddy * ddy)
            if dmin > Rs:
                continue
            ub[m] = mx - _envelope(code, R, rc, min(max(dmin - cell, 0.0), R))
            bid[m] = bi * nby + bj
            m += 1
    RR = Rs * Rs
    while True:
        k = -1
        top = best
        for q in range(m):
            if ub[q] > top:
                top = ub[q]
                k = q
        if k < 0:
            break
        ub[k] = -np.inf
        bi = bid[k] // nby
        bj = bid[k] - bi * nby
        for i in range(max(bi * B, i_lo), min(bi * B + B - 1, i_hi) + 1):
            ex = x0 + i * dx - qx
            for j in range(max(bj * B, j_lo), min(bj * B + B - 1, j_hi) + 1):
                vu = zu[i, j]
                if not (vu == vu) or vu < best:
                    continue
                v = z[i, j]
                ey = y0 + j * dy - qy
                d2 = ex * ex + ey * ey
                if d2 > RR:
                    continue
                d = math.sqrt(d2)
                g = v - _envelope(code, R, rc, min(d, R))
                if g > best or (g == best and d < bd):  # ties: the sample nearest the axis
                    best = g
                    bd = d
                    bi_ = i
                    bj_ = j
                # the most the surface around this sample (within ``cell``) could give: its
                # height raised by half its largest drop to a neighbour (the slope it sits
                # on), at its distance less ``cell``
                gu = vu - _envelope(code, R, rc, min(max(d - cell, 0.0), R))
                if d > R - cell and gu > band:
                    band = gu
                # keep the K best bounds (ties: the sample nearest the axis first)
                K = kv.shape[0]
                if gu > kv[K - 1] or (gu == kv[K - 1] and d < kd[K - 1]):
                    q = K - 1
                    while q > 0 and (gu > kv[q - 1] or (gu == kv[q - 1] and d < kd[q - 1])):
                        kv[q] = kv[q - 1]
                        kd[q] = kd[q - 1]
                        ki[q] = ki[q - 1]
                        kj[q] = kj[q - 1]
                        q -= 1
                    kv[q] = gu
                    kd[q] = d
                    ki[q] = i
                    kj[q] = j
    return best, bi_, bj_, band


@njit(cache=True, parallel=True)
def drop_samples(z, zu, x0, y0, dx, dy, bmax, B, code, R, rc, slack, cell, qx, qy, out, oi, oj, uout, ui, uj, bout,
                 w0, wi, wj):
    """Highest ``z[i, j] - envelope(min(|sample - axis|, R))`` over the samples within
    ``R + slack`` of each axis ``(qx[k], qy[k])``: ``out[k]`` (-inf: no sample) and the sample
    ``(oi[k], oj[k])``. With ``slack`` > 0 a sample just outside the disk stands for the
    surface between it and the rim (an upper bound, to be replaced by an exact contact).
    ``uout[k, :]``, ``(ui[k, :], uj[k, :])``: the K best bounds over the samples of what the
    surface within ``cell`` of a sample could give (its height, its distance less ``cell``),
    best first: where one beats ``out[k]``, the true contact may be near that sample instead.
    ``bout[k]``: the best such bound over the samples within ``cell`` of the rim, where a
    sliver of a feature may reach into the disk between samples. ``w0[k]`` at sample
    ``(wi[k], wj[k])`` (-1: none): a contact known already, the search's first bound (the
    outputs are the same with or without it: only blocks that cannot beat it are skipped)."""
    n = qx.shape[0]
    nbx, nby = bmax.shape
    cap = int((2.0 * (R + slack) / (dx * B) + 3.0) * (2.0 * (R + slack) / (dy * B) + 3.0)) + 4
    chunk = 512
    nch = (n + chunk - 1) // chunk
    for c in prange(nch):
        ub = np.empty(cap, dtype=np.float64)
        bid = np.empty(cap, dtype=np.int64)
        kd = np.empty(uout.shape[1], dtype=np.float64)
        for k in range(c * chunk, min(n, c * chunk + chunk)):
            v, a, b, bb = _drop_one(z, zu, x0, y0, dx, dy, bmax, B, code, R, rc, slack, cell, qx[k], qy[k],
                                    ub, bid, uout[k], kd, ui[k], uj[k], w0[k], wi[k], wj[k])
            bout[k] = bb
            out[k] = v
            oi[k] = a
            oj[k] = b
