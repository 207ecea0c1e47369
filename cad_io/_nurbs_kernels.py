"""Numba kernels for NURBS surface evaluation (Piegl & Tiller, The NURBS Book).

Only ``@njit(cache=True, error_model="numpy")`` code lives here: no validation, no exceptions for data reasons.
The public front door is :mod:`cad_io.nurbs`. Surfaces come packed (see
:func:`cad_io.nurbs.pack`):

``deg``   int64 (F, 2)   degrees (p, q), -1 for a face without surface
``ncp``   int64 (F, 2)   control point counts (nu, nv)
``koff``  int64 (F, 2)   offsets of face k's u and v knot vectors in ``knots``
``poff``  int64 (F,)     offset of face k's control points in ``cpw``
``knots`` float64 (K,)   knot vectors, concatenated, multiplicities expanded
``cpw``   float64 (N, 4) homogeneous control points (w x, w y, w z, w); face k's pole
                         (a, b) is row ``poff[k] + a * nv + b``

:func:`eval_point` evaluates one face at one (u, v) with all work arrays on the stack
(no heap allocation), so the sampler can call it inside its Newton loop.
"""

from __future__ import annotations

import numpy as np
from numba import carray, njit, prange, types
from numba.core import cgutils
from numba.extending import intrinsic

__all__ = [
    "MAX_DEGREE",
    "basis_ders",
    "eval_many",
    "eval_many_serial",
    "eval_point",
    "find_span",
    "project_points",
]

#: Highest degree the fixed-size stack work arrays hold.
MAX_DEGREE = 15
_M = MAX_DEGREE + 1


@intrinsic
def _stack_f64(typingctx, n):
    """A pointer to ``n`` float64 on the stack of the calling function (``n`` literal)."""
    if not isinstance(n, types.IntegerLiteral):
        return None
    count = n.literal_value

    def codegen(context, builder, signature, args):
        ty = context.get_value_type(types.float64)
        return cgutils.alloca_once(builder, ty, size=count)

    return types.CPointer(types.float64)(n), codegen


# _nrt=False: no reference counting on the calls from the Newton loops
# (cad_io._newton_kernels)
@njit(cache=True, error_model="numpy", _nrt=False)
def find_span(knots, off, n, p, u):
    """Knot span index of ``u`` (A2.1); ``n`` = number of control points - 1.

    Indices are relative to ``off``, the start of the knot vector in ``knots``.
    """
    if u >= knots[off + n + 1]:
        # last non-empty span
        s = n
        while s > p and knots[off + s] >= knots[off + n + 1]:
            s -= 1
        return s
    if u <= knots[off + p]:
        s = p
        while s < n and knots[off + s + 1] <= knots[off + p]:
            s += 1
        return s
    low = p
    high = n + 1
    mid = (low + high) // 2
    while u < knots[off + mid] or u >= knots[off + mid + 1]:
        if u < knots[off + mid]:
            high = mid
        else:
            low = mid
        mid = (low + high) // 2
    return mid


@njit(cache=True, error_model="numpy", _nrt=False)
def basis_ders(knots, off, span, u, p, nd, ders, ndu, a, left, right):
    """Non-zero basis functions and their derivatives up to ``nd`` (A2.3).

    Fills ``ders[k, j]`` = k-th derivative of N_{span-p+j, p} at ``u`` for k <= nd
    (zero for k > p). Work arrays: ``ndu`` (M, M), ``a`` (2, M), ``left``, ``right`` (M,).
    """
    ndu[0, 0] = 1.0
    for j in range(1, p + 1):
        left[j] = u - knots[off + span + 1 - j]
        right[j] = knots[off + span + j] - u
        saved = 0.0
        for r in range(j):
            ndu[j, r] = right[r + 1] + left[j - r]
            temp = ndu[r, j - 1] / ndu[j, r]
            ndu[r, j] = saved + right[r + 1] * temp
            saved = left[j - r] * temp
        ndu[j, j] = saved
    for j in range(p + 1):
        ders[0, j] = ndu[j, p]
    for k in range(1, nd + 1):
        for j in range(p + 1):
            ders[k, j] = 0.0
    n = min(p, nd)
    for r in range(p + 1):
        s1 = 0
        s2 = 1
        a[0, 0] = 1.0
        for k in range(1, n + 1):
            d = 0.0
            rk = r - k
            pk = p - k
            if r >= k:
                a[s2, 0] = a[s1, 0] / ndu[pk + 1, rk]
                d = a[s2, 0] * ndu[rk, pk]
            j1 = 1 if rk >= -1 else -rk
            j2 = k - 1 if r - 1 <= pk else p - r
            for j in range(j1, j2 + 1):
                a[s2, j] = (a[s1, j] - a[s1, j - 1]) / ndu[pk + 1, rk + j]
                d += a[s2, j] * ndu[rk + j, pk]
            if r <= pk:
                a[s2, k] = -a[s1, k - 1] / ndu[pk + 1, r]
                d += a[s2, k] * ndu[r, pk]
            ders[k, r] = d
            t = s1
            s1 = s2
            s2 = t
    rr = p
    for k in range(1, n + 1):
        for j in range(p + 1):
            ders[k, j] *= rr
        rr *= p - k


@njit(cache=True, error_model="numpy")
def eval_point(deg, ncp, koff, poff, knots, cpw, k, u, v, nderiv, out):
    """Point and derivatives of face ``k`` at (``u``, ``v``), into ``out``.

    Parameters
    ----------
    deg, ncp, koff, poff, knots, cpw : packed surfaces (module docstring)
    k : int
        Face index; the face must have a surface (``deg[k, 0] >= 0``) and degrees at most
        :data:`MAX_DEGREE` (checked by :func:`cad_io.nurbs.pack`).
    u, v : float
        Parameters; values outside the domain are clamped to it.
    nderiv : int
        0: ``out[0]`` = S; 1: also ``out[1]`` = Su, ``out[2]`` = Sv; 2: also ``out[3]`` =
        Suu, ``out[4]`` = Suv, ``out[5]`` = Svv.
    out : ndarray of shape (>= 1, 3, or 6, 3), float64
    """
    p = deg[k, 0]
    q = deg[k, 1]
    nu = ncp[k, 0]
    nv = ncp[k, 1]
    ku = koff[k, 0]
    kv = koff[k, 1]
    po = poff[k]
    nd = nderiv
    if nd > 2:  # noqa: PLR1730 (plain branches for numba)
        nd = 2
    if nd < 0:  # noqa: PLR1730
        nd = 0

    # clamp to the domain
    u0 = knots[ku + p]
    u1 = knots[ku + nu]
    v0 = knots[kv + q]
    v1 = knots[kv + nv]
    if u < u0:
        u = u0
    elif u > u1:
        u = u1
    if v < v0:
        v = v0
    elif v > v1:
        v = v1

    ndu = carray(_stack_f64(256), (_M, _M))
    wa = carray(_stack_f64(32), (2, _M))
    left = carray(_stack_f64(16), (_M,))
    right = carray(_stack_f64(16), (_M,))
    du = carray(_stack_f64(48), (3, _M))
    dv = carray(_stack_f64(48), (3, _M))
    skl = carray(_stack_f64(36), (3, 3, 4))
    tmp = carray(_stack_f64(12), (3, 4))

    su = find_span(knots, ku, nu - 1, p, u)
    sv = find_span(knots, kv, nv - 1, q, v)
    basis_ders(knots, ku, su, u, p, nd, du, ndu, wa, left, right)
    basis_ders(knots, kv, sv, v, q, nd, dv, ndu, wa, left, right)

    for a in range(3):
        for b in range(3):
            for c in range(4):
                skl[a, b, c] = 0.0
    # homogeneous derivatives: sum_i sum_j Nu^(a)_i Nv^(b)_j Pw_ij, a + b <= nd
    for i in range(p + 1):
        row = po + (su - p + i) * nv + (sv - q)
        for b in range(nd + 1):
            for c in range(4):
                tmp[b, c] = 0.0
        for j in range(q + 1):
            r = row + j
            x = cpw[r, 0]
            y = cpw[r, 1]
            z = cpw[r, 2]
            w = cpw[r, 3]
            for b in range(nd + 1):
                n = dv[b, j]
                tmp[b, 0] += n * x
                tmp[b, 1] += n * y
                tmp[b, 2] += n * z
                tmp[b, 3] += n * w
        for a in range(nd + 1):
            na = du[a, i]
            for b in range(nd + 1 - a):
                for c in range(4):
                    skl[a, b, c] += na * tmp[b, c]

    # rational derivatives (A4.4), binomials of order <= 2 are 1, 1, 2, 1
    w0 = skl[0, 0, 3]
    for c in range(3):
        s = skl[0, 0, c] / w0
        out[0, c] = s
    if nd >= 1:
        wu = skl[1, 0, 3]
        wv = skl[0, 1, 3]
        for c in range(3):
            s = out[0, c]
            su_ = (skl[1, 0, c] - wu * s) / w0
            sv_ = (skl[0, 1, c] - wv * s) / w0
            out[1, c] = su_
            out[2, c] = sv_
            if nd >= 2:
                out[3, c] = (skl[2, 0, c] - 2.0 * wu * su_ - skl[2, 0, 3] * s) / w0
                out[4, c] = (skl[1, 1, c] - wu * sv_ - wv * su_ - skl[1, 1, 3] * s) / w0
                out[5, c] = (skl[0, 2, c] - 2.0 * wv * sv_ - skl[0, 2, 3] * s) / w0


@njit(cache=True, error_model="numpy", parallel=True)
def eval_many(deg, ncp, koff, poff, knots, cpw, face, u, v, nderiv, out):
    """:func:`eval_point` over flat arrays ``face``, ``u``, ``v`` (n,) into ``out`` (n, r, 3).

    Faces without a surface (``deg[face, 0] < 0``) get NaN.
    """
    n = u.shape[0]
    nrow = out.shape[1]
    for i in prange(n):
        k = face[i]
        if deg[k, 0] < 0 or u[i] != u[i] or v[i] != v[i]:
            for a in range(nrow):
                for c in range(3):
                    out[i, a, c] = np.nan
        else:
            eval_point(deg, ncp, koff, poff, knots, cpw, k, u[i], v[i], nderiv, out[i])


@njit(cache=True, error_model="numpy")
def eval_many_serial(deg, ncp, koff, poff, knots, cpw, face, u, v, nderiv, out):
    """:func:`eval_many` on one thread (no thread-pool start-up for small batches)."""
    n = u.shape[0]
    nrow = out.shape[1]
    for i in range(n):
        k = face[i]
        if deg[k, 0] < 0 or u[i] != u[i] or v[i] != v[i]:
            for a in range(nrow):
                for c in range(3):
                    out[i, a, c] = np.nan
        else:
            eval_point(deg, ncp, koff, poff, knots, cpw, k, u[i], v[i], nderiv, out[i])


@njit(cache=True, error_model="numpy")
def _gauss_newton(deg, ncp, koff, poff, knots, cpw, k, px, py, pz, u, v, dom, buf):
    """Levenberg-damped Gauss-Newton for the (u, v) of face ``k`` nearest (px, py, pz).

    Returns (u, v, distance)."""
    eval_point(deg, ncp, koff, poff, knots, cpw, k, u, v, 1, buf)
    rx = buf[0, 0] - px
    ry = buf[0, 1] - py
    rz = buf[0, 2] - pz
    d2 = rx * rx + ry * ry + rz * rz
    lam = 1e-12
    for _ in range(60):
        a = buf[1, 0] * buf[1, 0] + buf[1, 1] * buf[1, 1] + buf[1, 2] * buf[1, 2]
        b = buf[1, 0] * buf[2, 0] + buf[1, 1] * buf[2, 1] + buf[1, 2] * buf[2, 2]
        c = buf[2, 0] * buf[2, 0] + buf[2, 1] * buf[2, 1] + buf[2, 2] * buf[2, 2]
        gu = buf[1, 0] * rx + buf[1, 1] * ry + buf[1, 2] * rz
        gv = buf[2, 0] * rx + buf[2, 1] * ry + buf[2, 2] * rz
        if d2 <= 1e-22:  # 1e-11 mm: on the surface
            break
        improved = False
        for _t in range(12):
            aa = a * (1.0 + lam) + 1e-300
            cc = c * (1.0 + lam) + 1e-300
            det = aa * cc - b * b
            if det <= 0.0:
                lam = lam * 10.0 + 1e-12
                continue
            du = -(cc * gu - b * gv) / det
            dv = -(aa * gv - b * gu) / det
            un = min(max(u + du, dom[0]), dom[1])
            vn = min(max(v + dv, dom[2]), dom[3])
            eval_point(deg, ncp, koff, poff, knots, cpw, k, un, vn, 1, buf)
            rx = buf[0, 0] - px
            ry = buf[0, 1] - py
            rz = buf[0, 2] - pz
            dn = rx * rx + ry * ry + rz * rz
            if dn < d2:
                step = abs(un - u) + abs(vn - v)
                u = un
                v = vn
                d2 = dn
                lam = max(lam * 0.1, 1e-15)
                improved = True
                if step <= 1e-15 * (1.0 + abs(u) + abs(v)):
                    improved = False
                break
            lam = lam * 10.0 + 1e-12
        if not improved:
            break
    eval_point(deg, ncp, koff, poff, knots, cpw, k, u, v, 1, buf)
    return u, v, np.sqrt(d2)


@njit(cache=True, error_model="numpy")
def project_points(deg, ncp, koff, poff, knots, cpw, k, pts, uv0, tol, uv, dist):
    """(u, v) on face ``k`` of the points ``pts`` (n, 3) that lie on (or near) it.

    Starts from ``uv0`` (n, 2); where that ends farther than ``tol`` (mm), restarts from the
    nearest point of a 17 x 17 parameter lattice. Fills ``uv`` (n, 2) and ``dist`` (n,).
    """
    buf = np.empty((6, 3))
    dom = np.empty(4)
    p = deg[k, 0]
    q = deg[k, 1]
    dom[0] = knots[koff[k, 0] + p]
    dom[1] = knots[koff[k, 0] + ncp[k, 0]]
    dom[2] = knots[koff[k, 1] + q]
    dom[3] = knots[koff[k, 1] + ncp[k, 1]]
    m = 17
    lat = np.empty((m, m, 3))
    mark = np.empty((4, 2), dtype=np.int64)
    for i in range(m):
        for j in range(m):
            eval_point(deg, ncp, koff, poff, knots, cpw, k,
                       dom[0] + (dom[1] - dom[0]) * i / (m - 1),
                       dom[2] + (dom[3] - dom[2]) * j / (m - 1), 0, buf)
            lat[i, j, 0] = buf[0, 0]
            lat[i, j, 1] = buf[0, 1]
            lat[i, j, 2] = buf[0, 2]
    for n in range(pts.shape[0]):
        px = pts[n, 0]
        py = pts[n, 1]
        pz = pts[n, 2]
        u = min(max(uv0[n, 0], dom[0]), dom[1])
        v = min(max(uv0[n, 1], dom[2]), dom[3])
        u, v, d = _gauss_newton(deg, ncp, koff, poff, knots, cpw, k, px, py, pz, u, v,
                                dom, buf)
        # restarts from the lattice points nearest first (several: a closed surface has
        # two lattice points at the same place, one of them stuck at the domain's end)
        tried = 0
        while d > tol and tried < 4:
            best = np.inf
            bi = -1
            bj = -1
            for i in range(m):
                for j in range(m):
                    if lat[i, j, 0] != lat[i, j, 0]:
                        continue
                    dx = lat[i, j, 0] - px
                    dy = lat[i, j, 1] - py
                    dz = lat[i, j, 2] - pz
                    dd = dx * dx + dy * dy + dz * dz
                    if dd < best:
                        best = dd
                        bi = i
                        bj = j
            if bi < 0:
                break
            mark[tried, 0] = bi
            mark[tried, 1] = bj
            lat[bi, bj, 0] = np.nan
            tried += 1
            u2, v2, d2 = _gauss_newton(deg, ncp, koff, poff, knots, cpw, k, px, py, pz,
                                       dom[0] + (dom[1] - dom[0]) * bi / (m - 1),
                                       dom[2] + (dom[3] - dom[2]) * bj / (m - 1), dom, buf)
            if d2 < d:
                u = u2
                v = v2
                d = d2
        for t in range(tried):  # restore the lattice
            i = mark[t, 0]
            j = mark[t, 1]
            eval_point(deg, ncp, koff, poff, knots, cpw, k,
                       dom[0] + (dom[1] - dom[0]) * i / (m - 1),
                       dom[2] + (dom[3] - dom[2]) * j / (m - 1), 0, buf)
            lat[i, j, 0] = buf[0, 0]
        uv[n, 0] = u
        uv[n, 1] = v
        dist[n] = d
