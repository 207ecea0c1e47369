"""numba kernels of the certified drop-cutter (:mod:`zmap.cam.bounds`): no validation, flat arrays.

The design is a grid of cells, each a bicubic Bezier patch given by its 4 x 4 control net
``nets[ci, cj, k, l]`` (``k`` along x, ``l`` along y; control point ``(k, l)`` sits at
``(x0 + (ci + k/3) dx, y0 + (cj + l/3) dy)``), a margin ``margin[ci, cj] >= 0`` by which the
design may rise above the patch (0: the patch is the design), and the nodes ``z[i, j]``,
exact points of the design (NaN: none). A cell without a patch has ``cmax = -inf``. A cell
with ``subidx[ci, cj] = k >= 0`` is flat sub-cells instead, ``sub[k]`` (n x n heights, NaN:
none): its contacts are exact on them (a flat cell's best point is its point nearest the axis).

For one axis position ``q`` the cutter-location height is the largest contact
``g(u) = h(u) - envelope(|u - q|)`` over the disk. The kernel keeps two numbers:

* a lower bound ``L``: the best contact at points of the design (the nodes) and of the patches
  (the corners of sub-patches, which lie on the patch);
* an upper bound of every cell that may beat it. Over a cell, ``envelope(|u - q|)`` is a convex
  function of ``u`` (a convex non-decreasing profile of a norm), so it lies above its tangent
  plane ``T`` at any point of the disk; a Bezier patch minus a plane is a Bezier patch whose
  control points are ``N_kl - T(greville_kl)`` (linear precision), and a patch lies below its
  highest control point (convex hull). So ``max(N_kl - T(p_kl)) + margin`` bounds every contact
  in the cell from above, with an error that shrinks with the square of the cell's size.

Cells whose bound beats ``L + eps`` are split (de Casteljau at the middle, four children)
depth first, the best child on top, until none does; a cell too small to split further, or one
that finds the stack full, keeps its bound. Every cell ends split, dropped with its bound or
kept with it, so the largest of ``L`` and those bounds is never below the true height; on exact
cells it is at most ``L + eps``, on cells with a margin above it by about their margin (a cell
is split while its patch's bound beats ``L``, and its margin rides on every bound it leaves).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ..sim._tool_kernels import _envelope as _env  # the lower envelope, d <= R

__all__ = ["cell_nets", "cell_max", "drop_bound", "patch_heights", "STACK"]

#: entries of the per-thread split stack (each 22 floats)
STACK = 4096


@njit(cache=True)
def _env_slope(code, R, rc, d):
    """d envelope / d distance at ``d`` (strictly inside the rim)."""
    if code == 0:
        return 0.0
    r0 = R - rc
    if d <= r0:
        return 0.0
    t = d - r0
    return t / math.sqrt(rc * rc - t * t)


@njit(cache=True)
def cell_nets(z, sx, sy, dx, dy, nets, cmax):
    """The control nets of every cell of a z-map's Bezier surface (:func:`zmap.interpolate.bezier`)
    from its heights and node slopes (:func:`zmap._interp_kernels.slope_tables`), and each net's
    highest point (``-inf`` where a corner is missing: no patch)."""
    nx, ny = z.shape
    for i in range(nx - 1):
        for j in range(ny - 1):
            z2 = z[i, j]
            z3 = z[i + 1, j]
            z6 = z[i, j + 1]
            z7 = z[i + 1, j + 1]
            if z2 != z2 or z3 != z3 or z6 != z6 or z7 != z7:
                cmax[i, j] = -np.inf
                for k in range(4):
                    for m in range(4):
                        nets[i, j, k, m] = np.nan
                continue
            P0, P1, P2, P3 = z2, z2 + sx[i, j] * dx / 3.0, z3 - sx[i + 1, j] * dx / 3.0, z3
            Q0, Q1, Q2, Q3 = z6, z6 + sx[i, j + 1] * dx / 3.0, z7 - sx[i + 1, j + 1] * dx / 3.0, z7
            a = sy[i, j] * dy / 3.0
            b = sy[i, j + 1] * dy / 3.0
            c = sy[i + 1, j] * dy / 3.0
            d = sy[i + 1, j + 1] * dy / 3.0
            best = -np.inf
            for k in range(4):
                P = P0 if k == 0 else (P1 if k == 1 else (P2 if k == 2 else P3))
                Q = Q0 if k == 0 else (Q1 if k == 1 else (Q2 if k == 2 else Q3))
                A = a + k * (c - a) / 3.0
                B = b + k * (d - b) / 3.0
                nets[i, j, k, 0] = P
                nets[i, j, k, 1] = P + A
                nets[i, j, k, 2] = Q - B
                nets[i, j, k, 3] = Q
                for m in range(4):
                    if nets[i, j, k, m] > best:
                        best = nets[i, j, k, m]
            cmax[i, j] = best


@njit(cache=True)
def cell_max(nets, cmax):
    """Each net's highest control point (``-inf`` for a net of NaN)."""
    for i in range(nets.shape[0]):
        for j in range(nets.shape[1]):
            best = -np.inf
            for k in range(4):
                for m in range(4):
                    v = nets[i, j, k, m]
                    if v > best:
                        best = v
            cmax[i, j] = best


@njit(cache=True)
def _bern(t, out):
    w = 1.0 - t
    out[0] = w * w * w
    out[1] = 3.0 * w * w * t
    out[2] = 3.0 * w * t * t
    out[3] = t * t * t


@njit(cache=True, parallel=True)
def patch_heights(nets, x0, y0, dx, dy, xs, ys, out):
    """Heights of the patches at points ``(xs, ys)`` (NaN outside the grid or without a patch)."""
    ncx, ncy = nets.shape[0], nets.shape[1]
    for p in prange(xs.shape[0]):
        bu = np.empty(4)
        bv = np.empty(4)
        fx = (xs[p] - x0) / dx
        fy = (ys[p] - y0) / dy
        i = int(math.floor(fx))
        j = int(math.floor(fy))
        if i == ncx and fx - ncx < 1e-9:
            i = ncx - 1
        if j == ncy and fy - ncy < 1e-9:
            j = ncy - 1
        if i < 0 or j < 0 or i >= ncx or j >= ncy:
            out[p] = np.nan
            continue
        _bern(fx - i, bu)
        _bern(fy - j, bv)
        s = 0.0
        for k in range(4):
            for m in range(4):
                s += bu[k] * bv[m] * nets[i, j, k, m]
        out[p] = s


@njit(cache=True)
def _net_at(net, u, v):
    """The patch of a flat (k-major) net at local (u, v) in [0, 1]^2."""
    wu = 1.0 - u
    wv = 1.0 - v
    bu0, bu1, bu2, bu3 = wu * wu * wu, 3.0 * wu * wu * u, 3.0 * wu * u * u, u * u * u
    bv0, bv1, bv2, bv3 = wv * wv * wv, 3.0 * wv * wv * v, 3.0 * wv * v * v, v * v * v
    s = 0.0
    for k in range(4):
        bk = bu0 if k == 0 else (bu1 if k == 1 else (bu2 if k == 2 else bu3))
        s += bk * (bv0 * net[4 * k] + bv1 * net[4 * k + 1] + bv2 * net[4 * k + 2] + bv3 * net[4 * k + 3])
    return s


@njit(cache=True)
def _split1(a0, a1, a2, a3, left, right, o):
    """de Casteljau at 1/2 of one cubic: ``left[o:o+4]``, ``right[o:o+4]``."""
    b0 = 0.5 * (a0 + a1)
    b1 = 0.5 * (a1 + a2)
    b2 = 0.5 * (a2 + a3)
    c0 = 0.5 * (b0 + b1)
    c1 = 0.5 * (b1 + b2)
    d0 = 0.5 * (c0 + c1)
    left[o] = a0
    left[o + 1] = b0
    left[o + 2] = c0
    left[o + 3] = d0
    right[o] = d0
    right[o + 1] = c1
    right[o + 2] = b2
    right[o + 3] = a3


@njit(cache=True)
def _plane_bound(net, xa, ya, sx, sy, qx, qy, code, R, rc, Rt, ux, uy, rim, nxr, nyr, v, w):
    """max over the cell of (patch - the envelope's tangent plane at (ux, uy), pulled inside
    ``Rt``), and across the rim (``rim``) the least of it plus ``lam * (R - (u - q).n)`` over
    lam >= 0: the disk lies on the inner side of the rim's tangent line along ``n``, where that
    term is >= 0, so adding it takes off what lies outside the disk (a flat end mill's rim has
    no envelope slope to do it)."""
    ox = ux - qx
    oy = uy - qy
    d = math.sqrt(ox * ox + oy * oy)
    if d > Rt:
        ox *= Rt / d
        oy *= Rt / d
        d = Rt
    e0 = _env(code, R, rc, d)
    gx = 0.0
    gy = 0.0
    if d > 0.0:
        s = _env_slope(code, R, rc, d)
        gx = s * ox / d
        gy = s * oy / d
    best = -np.inf
    for k in range(4):
        px = xa + k * sx / 3.0
        tx = gx * (px - qx - ox)
        for m in range(4):
            py = ya + m * sy / 3.0
            v[4 * k + m] = net[4 * k + m] - e0 - tx - gy * (py - qy - oy)
            w[4 * k + m] = R - (px - qx) * nxr - (py - qy) * nyr
            if v[4 * k + m] > best:
                best = v[4 * k + m]
    if rim:
        # min over lam >= 0 of max_q (v_q + lam w_q): walk the upper envelope of the 16 lines
        act = 0
        for q in range(1, 16):
            if v[q] > v[act] or (v[q] == v[act] and w[q] > w[act]):
                act = q
        lam = 0.0
        for _ in range(17):
            if w[act] >= 0.0:
                break
            nxt = -1
            bl = np.inf
            for q in range(16):
                if w[q] > w[act]:
                    l = (v[act] - v[q]) / (w[q] - w[act])
                    if l < bl or (l == bl and w[q] > w[nxt]):
                        bl = l
                        nxt = q
            if nxt < 0:
                break
            if bl > lam:
                lam = bl
            act = nxt
        b = v[act] + lam * w[act]
        if b < best:
            best = b
    return best


@njit(cache=True)
def _tangent_bound(net, xa, ya, sx, sy, qx, qy, code, R, rc, Rt, v, w):
    """An upper bound of every contact in the cell (the margin not included): the patch less
    the envelope's tangent plane at the cell's centre; across the rim also at the cell's point
    nearest the axis (the centre's plane there is steep and lifts the cell's inner side), the
    lesser of the two."""
    cxo = xa + 0.5 * sx - qx
    cyo = ya + 0.5 * sy - qy
    far = math.sqrt(max((cxo - 0.5 * sx) ** 2, (cxo + 0.5 * sx) ** 2)
                    + max((cyo - 0.5 * sy) ** 2, (cyo + 0.5 * sy) ** 2))
    nlen = math.sqrt(cxo * cxo + cyo * cyo)
    rim = far > R and nlen > 0.0
    nxr = cxo / nlen if nlen > 0.0 else 0.0
    nyr = cyo / nlen if nlen > 0.0 else 0.0
    best = _plane_bound(net, xa, ya, sx, sy, qx, qy, code, R, rc, Rt, xa + 0.5 * sx, ya + 0.5 * sy, rim, nxr, nyr,
                        v, w)
    if rim:
        nx_ = min(max(qx, xa), xa + sx)
        ny_ = min(max(qy, ya), ya + sy)
        b = _plane_bound(net, xa, ya, sx, sy, qx, qy, code, R, rc, Rt, nx_, ny_, rim, nxr, nyr, v, w)
        if b < best:
            best = b
    return best


@njit(cache=True)
def _dmin(qx, qy, xa, ya, xb, yb):
    """Distance from (qx, qy) to the rectangle [xa, xb] x [ya, yb]."""
    ex = 0.0
    if qx < xa:
        ex = xa - qx
    elif qx > xb:
        ex = qx - xb
    ey = 0.0
    if qy < ya:
        ey = ya - qy
    elif qy > yb:
        ey = qy - yb
    return math.sqrt(ex * ex + ey * ey)


@njit(cache=True)
def _drop_one(nets, cmax, margin, sub, subidx, z, x0, y0, dx, dy, bcell, bnode, B, code, R, rc, eps, min_size, qx, qy,
              sn, sr, sm, sb, res, tv, tw, tmp, half, sc):
    """One axis position: ``res = (cl, contact x, contact y, kept)``; cl -inf: no design under the disk."""
    nx, ny = z.shape
    ncx, ncy = cmax.shape
    Rt = R - 1e-7 * max(rc, 1e-3) if code != 0 else R
    L = -np.inf
    cx = np.nan
    cy = np.nan
    # the nodes: exact points of the design
    i0 = max(0, int(math.ceil((qx - R - x0) / dx)))
    i1 = min(nx - 1, int(math.floor((qx + R - x0) / dx)))
    j0 = max(0, int(math.ceil((qy - R - y0) / dy)))
    j1 = min(ny - 1, int(math.floor((qy + R - y0) / dy)))
    # the node nearest the axis first: a good lower bound prunes the rest
    ic = int(math.floor((qx - x0) / dx + 0.5))
    jc = int(math.floor((qy - y0) / dy + 0.5))
    if 0 <= ic < nx and 0 <= jc < ny:
        v = z[ic, jc]
        if v == v:
            ddx = x0 + ic * dx - qx
            ddy = y0 + jc * dy - qy
            d = math.sqrt(ddx * ddx + ddy * ddy)
            if d <= R:
                L = v - _env(code, R, rc, d)
                cx = x0 + ic * dx
                cy = y0 + jc * dy
    if i0 <= i1 and j0 <= j1:
        for bi in range(i0 // B, i1 // B + 1):
            for bj in range(j0 // B, j1 // B + 1):
                ia = max(i0, bi * B)
                ib = min(i1, bi * B + B - 1)
                ja = max(j0, bj * B)
                jb = min(j1, bj * B + B - 1)
                dm = _dmin(qx, qy, x0 + ia * dx, y0 + ja * dy, x0 + ib * dx, y0 + jb * dy)
                if dm > R or bnode[bi, bj] - _env(code, R, rc, dm) <= L:
                    continue
                for i in range(ia, ib + 1):
                    ddx = x0 + i * dx - qx
                    for j in range(ja, jb + 1):
                        v = z[i, j]
                        if not (v > L):
                            continue
                        ddy = y0 + j * dy - qy
                        d = math.sqrt(ddx * ddx + ddy * ddy)
                        if d <= R:
                            g = v - _env(code, R, rc, d)
                            if g > L:
                                L = g
                                cx = x0 + i * dx
                                cy = y0 + j * dy
    # the cells: bound, then split where a bound beats L
    c0 = max(0, int(math.floor((qx - R - x0) / dx)))
    c1 = min(ncx - 1, int(math.floor((qx + R - x0) / dx)))
    e0 = max(0, int(math.floor((qy - R - y0) / dy)))
    e1 = min(ncy - 1, int(math.floor((qy + R - y0) / dy)))
    top = 0
    Up = -np.inf
    U = -np.inf
    ux = np.nan
    uy = np.nan
    kept = 0
    if c0 <= c1 and e0 <= e1:
        for bi in range(c0 // B, c1 // B + 1):
            for bj in range(e0 // B, e1 // B + 1):
                ia = max(c0, bi * B)
                ib = min(c1, bi * B + B - 1)
                ja = max(e0, bj * B)
                jb = min(e1, bj * B + B - 1)
                dm = _dmin(qx, qy, x0 + ia * dx, y0 + ja * dy, x0 + (ib + 1) * dx, y0 + (jb + 1) * dy)
                if dm > R:
                    continue
                b = bcell[bi, bj] - _env(code, R, rc, dm)
                if b <= L + eps:
                    if b > Up:
                        Up = b
                    continue
                for i in range(ia, ib + 1):
                    xa = x0 + i * dx
                    for j in range(ja, jb + 1):
                        # a cell is split while its patch's bound beats L; its margin rides
                        # on every bound it leaves behind
                        mg = margin[i, j]
                        hm = cmax[i, j]
                        if not (hm > L + eps):
                            if hm + mg > L:  # may still lie above L: its envelope-aware bound counts
                                ya = y0 + j * dy
                                dm = _dmin(qx, qy, xa, ya, xa + dx, ya + dy)
                                b = hm + mg - _env(code, R, rc, min(dm, R))
                                if dm <= R and b > Up:
                                    Up = b
                            continue
                        ya = y0 + j * dy
                        dm = _dmin(qx, qy, xa, ya, xa + dx, ya + dy)
                        if dm > R:
                            continue
                        b = hm - _env(code, R, rc, dm)
                        if b <= L + eps:
                            if b + mg > Up:
                                Up = b + mg
                            continue
                        k = subidx[i, j]
                        if k >= 0:
                            # a flat cell of sub-cells, each flat: its contacts exactly
                            nsub = sub.shape[1]
                            hx = dx / nsub
                            hy = dy / nsub
                            b = -np.inf
                            bx = np.nan
                            by = np.nan
                            for a in range(nsub):
                                for c in range(nsub):
                                    v = sub[k, a, c]
                                    if not (v > L):
                                        continue
                                    sxa = xa + a * hx
                                    sya = ya + c * hy
                                    dm = _dmin(qx, qy, sxa, sya, sxa + hx, sya + hy)
                                    if dm > R:
                                        continue
                                    g = v - _env(code, R, rc, dm)
                                    if g > b:
                                        b = g
                                        bx = min(max(qx, sxa), sxa + hx)
                                        by = min(max(qy, sya), sya + hy)
                            if b > L + eps:
                                if b > U:
                                    U = b
                                    ux = bx
                                    uy = by
                                kept += 1
                            elif b > Up:
                                Up = b
                            continue
                        net = nets[i, j].ravel()
                        b = _tangent_bound(net, xa, ya, dx, dy, qx, qy, code, R, rc, Rt, tv, tw)
                        if b <= L + eps:
                            if b + mg > Up:
                                Up = b + mg
                            continue
                        b += mg
                        if top == sn.shape[0]:
                            if b > U:
                                U = b
                                ux = xa + 0.5 * dx
                                uy = ya + 0.5 * dy
                            kept += 1
                            continue
                        sn[top, :] = net
                        sr[top, 0] = xa
                        sr[top, 1] = ya
                        sr[top, 2] = dx
                        sr[top, 3] = dy
                        sm[top] = margin[i, j]
                        sb[top] = b
                        # the best cell on top
                        if top > 0 and sb[top] < sb[top - 1]:
                            for q in range(16):
                                t = sn[top, q]
                                sn[top, q] = sn[top - 1, q]
                                sn[top - 1, q] = t
                            for q in range(4):
                                t = sr[top, q]
                                sr[top, q] = sr[top - 1, q]
                                sr[top - 1, q] = t
                            t = sm[top]
                            sm[top] = sm[top - 1]
                            sm[top - 1] = t
                            t = sb[top]
                            sb[top] = sb[top - 1]
                            sb[top - 1] = t
                        top += 1
    colL = sc[0:4]
    colR = sc[4:8]
    kb = sc[8:12]
    while top > 0:
        top -= 1
        b = sb[top]
        mg = sm[top]
        if b - mg <= L + eps:
            if b > Up:
                Up = b
            continue
        xa = sr[top, 0]
        ya = sr[top, 1]
        sx = sr[top, 2]
        sy = sr[top, 3]
        if sx < min_size or top + 4 > sn.shape[0]:
            if b > U:
                U = b
                ux = xa + 0.5 * sx
                uy = ya + 0.5 * sy
            kept += 1
            continue
        for q in range(16):
            tmp[q] = sn[top, q]
        # split along x (k): half[0] left, half[1] right (as 4 x 4, k-major)
        for m in range(4):
            _split1(tmp[m], tmp[4 + m], tmp[8 + m], tmp[12 + m], colL, colR, 0)
            for k in range(4):
                half[0, 4 * k + m] = colL[k]
                half[1, 4 * k + m] = colR[k]
        # then along y (l): children 0 (x lo, y lo), 1 (x lo, y hi), 2 (x hi, y lo), 3 (x hi, y hi)
        for h in range(2):
            for k in range(4):
                _split1(half[h, 4 * k], half[h, 4 * k + 1], half[h, 4 * k + 2], half[h, 4 * k + 3], colL, colR, 0)
                for m in range(4):
                    tmp[m] = colL[m]
                for m in range(4):
                    half[2 + h, 4 * k + m] = colR[m]
                for m in range(4):
                    half[h, 4 * k + m] = tmp[m]
        hx = 0.5 * sx
        hy = 0.5 * sy
        # child c: x offset, y offset, net row in half
        base = top
        for c in range(4):
            ox = hx if c >= 2 else 0.0
            oy = hy if (c % 2) == 1 else 0.0
            row = (1 if c >= 2 else 0) + (2 if (c % 2) == 1 else 0)
            cxa = xa + ox
            cya = ya + oy
            if _dmin(qx, qy, cxa, cya, cxa + hx, cya + hy) > R:
                kb[c] = -np.inf
                continue
            net = half[row]
            # the child's corners lie on the patch
            for kk in range(2):
                for mm in range(2):
                    vx = cxa + kk * hx
                    vy = cya + mm * hy
                    ddx = vx - qx
                    ddy = vy - qy
                    d = math.sqrt(ddx * ddx + ddy * ddy)
                    if d <= R:
                        g = net[12 * kk + 3 * mm] - _env(code, R, rc, d)
                        if g > L:
                            L = g
                            cx = vx
                            cy = vy
            # across the rim: the rim point toward the child's centre, exact too (a
            # contact on the rim is between the corners at every size)
            ox = cxa + 0.5 * hx - qx
            oy = cya + 0.5 * hy - qy
            d = math.sqrt(ox * ox + oy * oy)
            if d > 0.0 and _dmin(qx, qy, cxa, cya, cxa + hx, cya + hy) < R < d + 0.7072 * (hx + hy):
                vx = qx + ox * R / d
                vy = qy + oy * R / d
                u = (vx - cxa) / hx
                w_ = (vy - cya) / hy
                if 0.0 <= u <= 1.0 and 0.0 <= w_ <= 1.0:
                    g = _net_at(net, u, w_) - _env(code, R, rc, R)
                    if g > L:
                        L = g
                        cx = vx
                        cy = vy
            kb[c] = _tangent_bound(net, cxa, cya, hx, hy, qx, qy, code, R, rc, Rt, tv, tw) + mg
        # push the children that may beat L, worst first (the best ends on top)
        for _ in range(4):
            w = -1
            wv = np.inf
            for c in range(4):
                if kb[c] - mg > L + eps and kb[c] < wv:
                    wv = kb[c]
                    w = c
            if w < 0:
                break
            c = w
            row = (1 if c >= 2 else 0) + (2 if (c % 2) == 1 else 0)
            for q in range(16):
                sn[base, q] = half[row, q]
            sr[base, 0] = xa + (hx if c >= 2 else 0.0)
            sr[base, 1] = ya + (hy if (c % 2) == 1 else 0.0)
            sr[base, 2] = hx
            sr[base, 3] = hy
            sm[base] = mg
            sb[base] = kb[c]
            kb[c] = -np.inf
            base += 1
        for c in range(4):
            if kb[c] > Up:
                Up = kb[c]
        top = base
    if U > L and U >= Up:
        res[0] = U
        res[1] = ux
        res[2] = uy
    else:
        # every cell not split to the end was dropped with a bound: the largest of them, when
        # above the best exact contact, keeps the answer on the safe side of the truth
        res[0] = Up if Up > L else L
        res[1] = cx
        res[2] = cy
    res[3] = kept


@njit(cache=True, parallel=True)
def drop_bound(nets, cmax, margin, sub, subidx, z, x0, y0, dx, dy, bcell, bnode, B, code, R, rc, eps, min_size, qx, qy,
               out, cxo, cyo, kept, chunk):
    """:func:`_drop_one` over every point, in chunks of ``chunk`` points (one stack per chunk)."""
    n = qx.shape[0]
    nch = (n + chunk - 1) // chunk
    for c in prange(nch):
        sn = np.empty((STACK, 16))
        sr = np.empty((STACK, 4))
        sm = np.empty(STACK)
        sb = np.empty(STACK)
        res = np.empty(4)
        tv = np.empty(16)
        tw = np.empty(16)
        tmp = np.empty(16)
        half = np.empty((4, 16))
        sc = np.empty(12)
        for p in range(c * chunk, min(n, (c + 1) * chunk)):
            _drop_one(nets, cmax, margin, sub, subidx, z, x0, y0, dx, dy, bcell, bnode, B, code, R, rc, eps, min_size,
                      qx[p], qy[p], sn, sr, sm, sb, res, tv, tw, tmp, half, sc)
            out[p] = res[0]
            cxo[p] = res[1]
            cyo[p] = res[2]
            kept[p] = res[3]
