"""Numba kernels of the sampler's 2D Jacobian inversion: the point and first derivatives of
a packed NURBS face (:func:`eval_d1`) and the damped Newton iteration ``x(u, v) = x_g,
y(u, v) = y_g`` on it (:func:`_newton`); no validation here.

The pair solver (:mod:`cad_io._sample_kernels`) calls :func:`_newton` once or more per
pair, so nearly all of a map's time is spent here; the helpers run with ``_nrt=False``
(see :mod:`cad_io._sample_kernels`).
"""

from __future__ import annotations

import math

from numba import njit

from ._nurbs_kernels import _stack_f64, find_span

__all__ = ["_newton", "eval_d1"]


@njit(cache=True, error_model="numpy", _nrt=False)
def _basis_d1(knots, off, span, u, p, N, D, left, right):
    """Non-zero basis functions ``N[j]`` = N_{span-p+j, p}(u) and their first derivatives
    ``D[j]`` (The NURBS Book A2.2, with the derivative taken from the degree p-1 values
    in its last round: N'_{i,p} = p (N_{i,p-1} / (u_{i+p} - u_i) - N_{i+1,p-1} /
    (u_{i+p+1} - u_{i+1}))). The same numbers as ``_nurbs_kernels.basis_ders`` with
    ``nd = 1``, without its general table of derivatives."""
    N[0] = 1.0
    D[0] = 0.0
    for j in range(1, p + 1):
        left[j] = u - knots[off + span + 1 - j]
        right[j] = knots[off + span + j] - u
        saved = 0.0
        if j == p:
            dsaved = 0.0
            for r in range(j):
                temp = N[r] / (right[r + 1] + left[j - r])
                D[r] = dsaved - p * temp
                dsaved = p * temp
                N[r] = saved + right[r + 1] * temp
                saved = left[j - r] * temp
            D[j] = dsaved
        else:
            for r in range(j):
                temp = N[r] / (right[r + 1] + left[j - r])
                N[r] = saved + right[r + 1] * temp
                saved = left[j - r] * temp
        N[j] = saved


@njit(cache=True, error_model="numpy", _nrt=False)
def eval_d1(deg, ncp, koff, poff, knots, cpw, k, u, v, out):
    """Point and first derivatives of face ``k`` at (``u``, ``v``): ``out[0]`` = S,
    ``out[1]`` = S_u, ``out[2]`` = S_v (u, v clamped to the domain).

    ``_nurbs_kernels.eval_point(..., nderiv=1, out)`` specialised for the Newton loop of
    the sampler, where it is nearly all the time: the basis functions and their first
    derivatives in one pass (:func:`_basis_d1`) and the tensor product in scalars, about
    2x faster. ``tests/cad_io/test_sample.py`` holds it to ``eval_point`` on real faces.
    """
    _eval_d1_face(knots, cpw, _face(deg, ncp, koff, poff, k), u, v, out)


@njit(cache=True, error_model="numpy", _nrt=False)
def _face(deg, ncp, koff, poff, k):
    """Face ``k``'s ``(p, q, nu, nv, ku, kv, po)``: degrees, pole counts, knot and pole offsets."""
    return deg[k, 0], deg[k, 1], ncp[k, 0], ncp[k, 1], koff[k, 0], koff[k, 1], poff[k]


@njit(cache=True, error_model="numpy", _nrt=False)
def _eval_d1_face(knots, cpw, face, u, v, out):
    """:func:`eval_d1` on the face ``face`` = :func:`_face` (the Newton loop reads it once:
    three arrays fewer to pass per call)."""
    p, q, nu, nv, ku, kv, po = face
    u0 = knots[ku + p]
    u1 = knots[ku + nu]
    v0 = knots[kv + q]
    v1 = knots[kv + nv]
    u = min(max(u, u0), u1)
    v = min(max(v, v0), v1)
    Nu = _stack_f64(16)
    Du = _stack_f64(16)
    Nv = _stack_f64(16)
    Dv = _stack_f64(16)
    left = _stack_f64(16)
    right = _stack_f64(16)
    su = find_span(knots, ku, nu - 1, p, u)
    sv = find_span(knots, kv, nv - 1, q, v)
    _basis_d1(knots, ku, su, u, p, Nu, Du, left, right)
    _basis_d1(knots, kv, sv, v, q, Nv, Dv, left, right)
    sx = 0.0
    sy = 0.0
    sz = 0.0
    sw = 0.0
    ux = 0.0
    uy = 0.0
    uz = 0.0
    uw = 0.0
    vx = 0.0
    vy = 0.0
    vz = 0.0
    vw = 0.0
    for i in range(p + 1):
        row = po + (su - p + i) * nv + (sv - q)
        tx = 0.0
        ty = 0.0
        tz = 0.0
        tw = 0.0
        dx = 0.0
        dy = 0.0
        dz = 0.0
        dw = 0.0
        for j in range(q + 1):
            r = row + j
            n = Nv[j]
            d = Dv[j]
            x = cpw[r, 0]
            y = cpw[r, 1]
            z = cpw[r, 2]
            w = cpw[r, 3]
            tx += n * x
            ty += n * y
            tz += n * z
            tw += n * w
            dx += d * x
            dy += d * y
            dz += d * z
            dw += d * w
        a = Nu[i]
        b = Du[i]
        sx += a * tx
        sy += a * ty
        sz += a * tz
        sw += a * tw
        ux += b * tx
        uy += b * ty
        uz += b * tz
        uw += b * tw
        vx += a * dx
        vy += a * dy
        vz += a * dz
        vw += a * dw
    iw = 1.0 / sw
    X = sx * iw
    Y = sy * iw
    Z = sz * iw
    out[0, 0] = X
    out[0, 1] = Y
    out[0, 2] = Z
    out[1, 0] = (ux - uw * X) * iw
    out[1, 1] = (uy - uw * Y) * iw
    out[1, 2] = (uz - uw * Z) * iw
    out[2, 0] = (vx - vw * X) * iw
    out[2, 1] = (vy - vw * Y) * iw
    out[2, 2] = (vz - vw * Z) * iw


#: Newton stops once converged in xy and its next step moves the point less than this (mm)
_STEP_TOL2 = 1e-9 ** 2


@njit(cache=True, error_model="numpy", _nrt=False)
def _newton(deg, ncp, koff, poff, knots, cpw, k, u, v, xg, yg, u0, u1, v0, v1, tol, max_iter, out):
    """Damped Newton for x(u, v) = xg, y(u, v) = yg on face ``k`` from (u, v).

    Returns ``(converged, u, v, at_edge, singular)``; ``out[0]`` holds the point at the
    last (u, v) (``at_edge``: stopped on the domain boundary, i.e. the answer lies outside
    the face; ``singular``: stopped on a rank-deficient xy Jacobian, a vertical face).
    """
    u = min(max(u, u0), u1)
    v = min(max(v, v0), v1)
    face = _face(deg, ncp, koff, poff, k)
    _eval_d1_face(knots, cpw, face, u, v, out)
    fx = out[0, 0] - xg
    fy = out[0, 1] - yg
    r = math.sqrt(fx * fx + fy * fy)
    for it in range(max_iter):
        sux = out[1, 0]
        suy = out[1, 1]
        svx = out[2, 0]
        svy = out[2, 1]
        det = sux * svy - svx * suy
        nsu = out[1, 0] ** 2 + out[1, 1] ** 2 + out[1, 2] ** 2
        nsv = out[2, 0] ** 2 + out[2, 1] ** 2 + out[2, 2] ** 2
        if not (abs(det) > 1e-10 * math.sqrt(nsu * nsv)):
            # singular: vertical wall or fold
            return r <= tol, u, v, r > tol and (u == u0 or u == u1 or v == v0 or v == v1), True
        du = -(svy * fx - svx * fy) / det
        dv = -(-suy * fx + sux * fy) / det
        if r <= tol:
            # converged in xy; but near a fold (a silhouette seen from the view axis: the
            # tangent line of a fillet and an edge-on top face) the xy residual falls with
            # the square of the distance to the answer, and r = 1e-10 leaves the height
            # 2e-5 mm off on a 5 mm fillet: go on while the step moves the point in 3D
            sx = out[1, 0] * du + out[2, 0] * dv
            sy = out[1, 1] * du + out[2, 1] * dv
            sz = out[1, 2] * du + out[2, 2] * dv
            if sx * sx + sy * sy + sz * sz <= _STEP_TOL2:
                return True, u, v, False, False
        lam = 1.0
        improved = False
        un = u
        vn = v
        rn = r
        for h in range(12):
            un = min(max(u + lam * du, u0), u1)
            vn = min(max(v + lam * dv, v0), v1)
            _eval_d1_face(knots, cpw, face, un, vn, out)
            fx = out[0, 0] - xg
            fy = out[0, 1] - yg
            rn = math.sqrt(fx * fx + fy * fy)
            if rn < r:
                improved = True
                break
            lam *= 0.5
        if not improved and r <= tol:
            # rounding stops the fold's refinement: keep the converged point
            _eval_d1_face(knots, cpw, face, u, v, out)
            return True, u, v, False, False
        u = un
        v = vn
        r = rn
        if not improved:
            break
    if r <= tol:
        return True, u, v, False, False
    return False, u, v, (u == u0 or u == u1 or v == v0 or v == v1), False
