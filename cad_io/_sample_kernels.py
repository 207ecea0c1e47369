"""Numba kernels of the z-map sampler (:mod:`cad_io.sampler`); no validation here.

The sampler works on *pairs* (grid point, mesh triangle that covers it in xy): every pair
is one candidate height. :func:`count_pairs` and :func:`fill_pairs` rasterise the
triangles onto the grid (barycentric weights of the grid point in the triangle),
:func:`solve_pairs` turns each pair into a height (2D Jacobian inversion on the face's
NURBS from the barycentric (u, v), or the triangle's exact barycentric height), and
:func:`reduce_pairs` keeps the top-most candidate per grid point.

Status codes (the ``method`` layer): 0 no height, 1 Jacobian inversion, 2 facet.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ._nurbs_kernels import _gauss_newton, _stack_f64, find_span

__all__ = ["count_pairs", "count_pairs_xy", "eval_d1", "fill_pairs", "fill_pairs_xy", "in_tolerance", "mesh_distance",
           "point_in_bands", "point_in_loops", "points_in_loops", "project_candidates", "reduce_pairs", "solve_pairs", "solve_pairs_xy"]

#: triangles whose xy area is below this share of their squared longest edge are treated
#: as vertical (they cover no grid point)
_FLAT_EPS = 1e-12

# Helpers are plain @njit calls (inlining them at numba IR level, ``inline="always"``, made
# the cold compile of this module 3x longer). The ones on the per-pair path that allocate
# nothing run with ``_nrt=False``: no reference counting of their array arguments, which
# otherwise costs two atomic operations per array per call (+25% on the Newton loop, which
# calls eval_d1 with seven arrays).


@njit(cache=True, error_model="numpy")
def _bary_limits(ax, ay, bx, by, cx, cy, area, margin):
    """Lower bounds of the barycentric weights (w0, w1, w2) that admit points up to
    ``margin`` (xy, mm) outside the triangle: w_k >= -margin * |opposite edge| / |area|.

    ``area`` is twice the signed xy area. ``margin`` 0 gives the exact triangle (with a
    1e-12 rounding slack).
    """
    if margin <= 0.0:
        return -1e-12, -1e-12, -1e-12
    f = margin / abs(area)
    la = math.sqrt((cx - bx) ** 2 + (cy - by) ** 2)
    lb = math.sqrt((ax - cx) ** 2 + (ay - cy) ** 2)
    lc = math.sqrt((bx - ax) ** 2 + (by - ay) ** 2)
    return -1e-12 - f * la, -1e-12 - f * lb, -1e-12 - f * lc


@njit(cache=True, error_model="numpy", parallel=True)
def count_pairs(nodes, tris, tri_margin, x0, y0, dx, dy, nx, ny, counts):
    """Number of grid points inside each triangle's xy projection, into ``counts`` (M,).

    ``tri_margin`` (M,): how far (mm) outside its triangle a point still pairs with it: the
    mesh deflection on triangles at a face's mesh boundary, whose polygon may cut inside
    the true (curved) boundary; 0 elsewhere.
    """
    no_i = np.empty(0, dtype=np.int64)
    no_w = np.empty((0, 2))
    for t in prange(tris.shape[0]):
        counts[t] = _scan_grid_tri(nodes, tris, tri_margin, t, x0, y0, dx, dy, nx, ny, 0, no_i, no_i, no_w, False)


@njit(cache=True, error_model="numpy", parallel=True)
def fill_pairs(nodes, tris, tri_margin, t0, offsets, x0, y0, dx, dy, nx, ny, gidx, tri, w):
    """Grid index, triangle and barycentric weights of every pair of triangles t0.. .

    ``offsets[t - t0]`` is where triangle ``t``'s pairs start (its count from
    :func:`count_pairs`, cumulated); ``gidx`` (P,) int64 = ``i * ny + j``, ``tri`` (P,) int64,
    ``w`` (P, 2) float64 = weights of the triangle's 2nd and 3rd node.
    """
    for tt in prange(offsets.shape[0] - 1):
        if offsets[tt + 1] == offsets[tt]:
            continue
        _scan_grid_tri(nodes, tris, tri_margin, t0 + tt, x0, y0, dx, dy, nx, ny, offsets[tt], gidx, tri, w, True)


@njit(cache=True, error_model="numpy", _nrt=False)
def _tri_xy(nodes, tris, t):
    """xy of triangle ``t``'s corners and twice its signed xy area; the area is 0 where the
    triangle is vertical or degenerate in xy (below ``_FLAT_EPS`` of its squared longest
    edge, or NaN)."""
    a = tris[t, 0]
    b = tris[t, 1]
    c = tris[t, 2]
    ax = nodes[a, 0]
    ay = nodes[a, 1]
    bx = nodes[b, 0]
    by = nodes[b, 1]
    cx = nodes[c, 0]
    cy = nodes[c, 1]
    area = (bx - ax) * (cy - ay) - (cx - ax) * (by - ay)
    l2 = max((bx - ax) ** 2 + (by - ay) ** 2, max((cx - ax) ** 2 + (cy - ay) ** 2, (cx - bx) ** 2 + (cy - by) ** 2))
    if not (abs(area) > _FLAT_EPS * l2 and area == area):
        area = 0.0
    return ax, ay, bx, by, cx, cy, area


@njit(cache=True, error_model="numpy", _nrt=False)
def _scan_grid_tri(nodes, tris, tri_margin, t, x0, y0, dx, dy, nx, ny, p, gidx, tri, w, fill):
    """Count (``fill`` False) or write from ``p`` (``fill`` True) the grid points in triangle ``t``."""
    ax, ay, bx, by, cx, cy, area = _tri_xy(nodes, tris, t)
    if area == 0.0:
        return 0  # vertical (or degenerate) in xy: covers no grid point
    inv = 1.0 / area
    mg = tri_margin[t]
    l0, l1, l2_ = _bary_limits(ax, ay, bx, by, cx, cy, area, mg)
    i0, i1, j0, j1 = _widened_window(ax, ay, bx, by, cx, cy, x0, y0, dx, dy, nx, ny, l0, l1, l2_)
    n = 0
    for i in range(i0, i1 + 1):
        px = x0 + i * dx
        for j in range(j0, j1 + 1):
            py = y0 + j * dy
            w1 = ((px - ax) * (cy - ay) - (cx - ax) * (py - ay)) * inv
            w2 = ((bx - ax) * (py - ay) - (px - ax) * (by - ay)) * inv
            if w1 >= l1 and w2 >= l2_ and 1.0 - w1 - w2 >= l0:
                if fill:
                    gidx[p + n] = i * ny + j
                    tri[p + n] = t
                    w[p + n, 0] = w1
                    w[p + n, 1] = w2
                n += 1
    return n


@njit(cache=True, error_model="numpy")
def point_in_loops(u, v, loop_uv, loop_off, first, last, eps):
    """Even-odd test of (u, v) against loops ``first..last-1`` (``loop_off`` bounds in ``loop_uv``).

    Points within ``eps`` of a loop edge count as inside (a grid point on a face's
    boundary belongs to the face).
    """
    inside = False
    eps2 = eps * eps
    for L in range(first, last):
        s = loop_off[L]
        e = loop_off[L + 1]
        n = e - s
        for m in range(n):
            ua = loop_uv[s + m, 0]
            va = loop_uv[s + m, 1]
            mb = m + 1
            if mb == n:
                mb = 0
            ub = loop_uv[s + mb, 0]
            vb = loop_uv[s + mb, 1]
            hit = _edge_test(u, v, ua, va, ub, vb, eps2)
            if hit == 2:
                return True
            if hit == 1:
                inside = not inside
    return inside


@njit(cache=True, error_model="numpy", parallel=True)
def points_in_loops(us, vs, loop_uv, loop_off, eps, out):
    """:func:`point_in_loops` of every ``(us[i], vs[i])`` against all loops, into ``out`` (bool)."""
    n_loops = loop_off.shape[0] - 1
    for i in prange(us.shape[0]):
        out[i] = point_in_loops(us[i], vs[i], loop_uv, loop_off, 0, n_loops, eps)


@njit(cache=True, error_model="numpy", _nrt=False)
def point_in_bands(u, v, edges, band_ptr, band_edges, first, nband, vlo, h, eps):
    """:func:`point_in_loops` on a face's loop edges bucketed in ``nband`` bands of v.

    Band ``b`` (``vlo + b*h`` .. ``vlo + (b+1)*h``, widened by the edges' slack) lists, in
    ``band_edges[band_ptr[first + b]:band_ptr[first + b + 1]]``, every edge (row of
    ``edges`` = ua, va, ub, vb and, where present, the edge's own slack in uv and its
    bulge) whose v-range meets it, so a point tests only its band. A point within ``eps``
    or the edge's own slack of an edge counts as inside.

    The bulge ``kb`` (column 5, uv) places the true trim curve beside each chord of the
    polygon: at ``kb * s * (1 - s)`` to the chord's left at fraction ``s`` along it (a
    parabola through the chord's ends and the curve's point at the chord's middle). The
    slack is then measured to that curve, and a point between the chord and the curve
    (where the polygon and the face disagree) has its even-odd answer flipped: the test
    follows the curve to far below the polygon's chordal error.
    """
    fb = (v - vlo) / h
    if fb < -1.0 or fb > nband + 1.0:
        return False
    b = int(math.floor(fb))
    b = min(max(b, 0), nband - 1)
    inside = False
    own = edges.shape[1] > 4
    lens = edges.shape[1] > 5
    for q in range(band_ptr[first + b], band_ptr[first + b + 1]):
        e = band_edges[q]
        ua = edges[e, 0]
        va = edges[e, 1]
        ub = edges[e, 2]
        vb = edges[e, 3]
        se = eps
        if own:
            se = max(eps, edges[e, 4])
        if lens and edges[e, 5] != 0.0:
            hit = _edge_test_bulged(u, v, ua, va, ub, vb, edges[e, 5], se * se)
        else:
            hit = _edge_test(u, v, ua, va, ub, vb, se * se)
        if hit == 2:
            return True
        if hit == 1:
            inside = not inside
    return inside


@njit(cache=True, error_model="numpy", _nrt=False)
def in_tolerance(u, v, x, y, z, k, edges, band_ptr, band_edges, face_bi, face_bf):
    """True where a point of face ``k``'s surface outside its trim loops is on the face
    within the tolerance of its edges in the file, as OCC's ray cast counts it.

    The trim arrays of :func:`point_in_bands` carry the band too (one call with few
    arguments: each array passed per pair costs, 15-25% of the die's pair loop for five
    more): ``face_bf[k, 3:11]`` = the face's largest edge tolerance t (mm; 0: no band), the
    uv distance OCC classifies at it, the face's uv bounds u0, u1, v0, v1, the start and
    height of its segment bands along x; ``face_bi[k, 2:4]`` = its first segment band (in
    ``band_ptr``) and their number; a segment row of ``edges`` is x0, y0, z0, x1, y1, z1.
    The point ((u, v) on the surface, (x, y, z) in space) must lie in the uv bounds, within
    the uv distance of one of the face's loop edges (the edges of its band of v; the bands
    reach that far) and within t in space of one of its edges' 3D curves:
    IntCurvesFace_Intersector's ON test with its boundary tolerance (the 2D classification
    at the uv resolution of the largest edge tolerance, then the point's distance to the
    nearest edge curve).
    """
    t3 = face_bf[k, 3]
    if not (t3 > 0.0) or face_bi[k, 1] == 0:
        return False
    if u < face_bf[k, 5] or u > face_bf[k, 6] or v < face_bf[k, 7] or v > face_bf[k, 8]:
        return False  # beyond the face's uv bounds, where OCC's intersector sees no surface
    nband = face_bi[k, 1]
    fb = (v - face_bf[k, 0]) / face_bf[k, 1]
    if fb < 0.0 or fb >= nband:
        return False
    b = min(int(math.floor(fb)), nband - 1)
    t2 = face_bf[k, 4] * face_bf[k, 4]
    near = False
    first = face_bi[k, 0]
    for q in range(band_ptr[first + b], band_ptr[first + b + 1]):
        e = band_edges[q]
        if _edge_test(u, v, edges[e, 0], edges[e, 1], edges[e, 2], edges[e, 3], t2) == 2:
            near = True
            break
    if not near:
        return False
    nsb = face_bi[k, 3]
    fx = (x - face_bf[k, 9]) / face_bf[k, 10]
    if nsb == 0 or fx < 0.0 or fx >= nsb:
        return False
    sb = face_bi[k, 2] + min(int(math.floor(fx)), nsb - 1)
    t3 *= t3
    for m in range(band_ptr[sb], band_ptr[sb + 1]):
        q = band_edges[m]
        ax = edges[q, 0]
        ay = edges[q, 1]
        az = edges[q, 2]
        ex = edges[q, 3] - ax
        ey = edges[q, 4] - ay
        ez = edges[q, 5] - az
        ll = ex * ex + ey * ey + ez * ez
        s_ = 0.0
        if ll > 0.0:
            s_ = min(max(((x - ax) * ex + (y - ay) * ey + (z - az) * ez) / ll, 0.0), 1.0)
        dx_ = x - (ax + s_ * ex)
        dy_ = y - (ay + s_ * ey)
        dz_ = z - (az + s_ * ez)
        if dx_ * dx_ + dy_ * dy_ + dz_ * dz_ <= t3:
            return True
    return False


@njit(cache=True, error_model="numpy", _nrt=False)
def _edge_test_bulged(u, v, ua, va, ub, vb, kb, eps2):
    """:func:`_edge_test` against a chord whose true curve bulges ``kb * s * (1 - s)`` to its
    left: 2 within sqrt(eps2) of the curve; else 1 where the +u ray crosses the chord XOR the
    point lies between the chord and the curve; else 0."""
    eu = ub - ua
    ev = vb - va
    ll = eu * eu + ev * ev
    if not (ll > 0.0):
        return _edge_test(u, v, ua, va, ub, vb, eps2)
    t = ((u - ua) * eu + (v - va) * ev) / ll
    between = False
    if 0.0 <= t <= 1.0:
        h = (eu * (v - va) - ev * (u - ua)) / math.sqrt(ll)
        c = kb * t * (1.0 - t)
        if (h - c) * (h - c) <= eps2:
            return 2
        between = (0.0 < h < c) or (c < h < 0.0)
    else:
        da = (u - ua) * (u - ua) + (v - va) * (v - va)
        db = (u - ub) * (u - ub) + (v - vb) * (v - vb)
        if min(da, db) <= eps2:
            return 2
    cross = False
    if (va > v) != (vb > v):
        ux = ua + (v - va) * (ub - ua) / (vb - va)
        cross = u < ux
    return 1 if cross != between else 0


@njit(cache=True, error_model="numpy", _nrt=False)
def _edge_test(u, v, ua, va, ub, vb, eps2):
    """One loop edge against (u, v): 2 if the point is within sqrt(eps2) of the edge, 1 if
    the edge crosses the ray from the point towards +u (even-odd rule), else 0."""
    eu = ub - ua
    ev = vb - va
    ll = eu * eu + ev * ev
    s_ = 0.0
    if ll > 0.0:
        s_ = min(max(((u - ua) * eu + (v - va) * ev) / ll, 0.0), 1.0)
    du_ = u - (ua + s_ * eu)
    dv_ = v - (va + s_ * ev)
    if du_ * du_ + dv_ * dv_ <= eps2:
        return 2
    if (va > v) != (vb > v):
        ux = ua + (v - va) * (ub - ua) / (vb - va)
        if u < ux:
            return 1
    return 0


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


#: |n_z| below which a mesh triangle is a wall for the facet fallback (steeper than ~75 deg)
_WALL_NZ = 0.25


@njit(cache=True, error_model="numpy", _nrt=False)
def _tri_nz(nodes, a, b, c):
    """|n_z| of triangle (a, b, c): 1 flat, 0 vertical (0 for a degenerate triangle)."""
    ux = nodes[b, 0] - nodes[a, 0]
    uy = nodes[b, 1] - nodes[a, 1]
    uz = nodes[b, 2] - nodes[a, 2]
    vx = nodes[c, 0] - nodes[a, 0]
    vy = nodes[c, 1] - nodes[a, 1]
    vz = nodes[c, 2] - nodes[a, 2]
    nx = uy * vz - uz * vy
    ny = uz * vx - ux * vz
    nz = ux * vy - uy * vx
    nn = math.sqrt(nx * nx + ny * ny + nz * nz)
    return abs(nz) / nn if nn > 0.0 else 0.0


@njit(cache=True, error_model="numpy", _nrt=False)
def _wall_triangle(nodes, a, b, c):
    """True where triangle (a, b, c) is steeper than ~75 degrees (|n_z| < ``_WALL_NZ``).

    Newton is singular on a vertical face (its xy Jacobian has rank 1), so every point of
    such a face falls to the facet path; but a facet height on a steep triangle is
    uncertain by the mesh's xy error over |n_z|, and BRepMesh does not always hold the
    deflection there: on featuretype's extruded B-spline wall (face 78) 1.2 mm chord
    triangles with |n_z| = 0.063 answered 18.3-19.4 mm up to 80 um off the wall, where the
    floor is at 15.875 mm and OCC's ray cast sees the floor. So where Newton stopped on a
    singular Jacobian and the triangle is this steep, the face is a wall there and gives no
    height (the faces beside it give the top-most heights). Where Newton fails on a steep
    face for another reason the facet still answers: on cornetta's 86 degree faces 32 and
    99 leaving it out let the floor 40 mm below answer.
    """
    return _tri_nz(nodes, a, b, c) < _WALL_NZ


@njit(cache=True, error_model="numpy", _nrt=False)
def _facet_pair(p, tri, w, nodes, tris, z, status):
    """Facet height of pair ``p`` (``mode`` 2 or a facets-only face), into ``z[p]``, ``status[p]``.

    Apart from :func:`_solve_one`: small enough to be inlined in the pair loop, where a
    call with _solve_one's 29 arguments made the facet path 20% slower.
    """
    t = tri[p]
    w1 = w[p, 0]
    w2 = w[p, 1]
    w0 = 1.0 - w1 - w2
    if min(w0, min(w1, w2)) < -1e-12:
        z[p] = np.nan  # paired by the boundary margin: only an exact solution may answer
        status[p] = 0
    else:
        z[p] = w0 * nodes[tris[t, 0], 2] + w1 * nodes[tris[t, 1], 2] + w2 * nodes[tris[t, 2], 2]
        status[p] = 2


@njit(cache=True, error_model="numpy", _nrt=False)
def _solve_one(p, xg, yg, tri, w, nodes, uv, tris, tri_face, tri_check, face_mode, face_zgap,
               deg, ncp, koff, poff, knots, cpw, domain, edges, band_ptr, band_edges, face_bi, face_bf,
               mode, tol, max_iter, z, status, out):
    """Height candidate of pair ``p`` at the world point (xg, yg), into ``z[p]`` and ``status[p]``.

    The one solver behind :func:`solve_pairs` (grid points) and :func:`solve_pairs_xy`
    (scattered points): Newton from the barycentric (u, v) and, where that runs off the
    domain, from the triangle's nodes; the facet-height check; the trim test on boundary
    triangles; the facet fallback. (Pairs that take the facet height outright, ``mode`` 2
    or a facets-only face, go to :func:`_facet_pair` instead.)
    """
    t = tri[p]
    k = tri_face[t]
    a = tris[t, 0]
    b = tris[t, 1]
    c = tris[t, 2]
    w1 = w[p, 0]
    w2 = w[p, 1]
    w0 = 1.0 - w1 - w2
    zf = w0 * nodes[a, 2] + w1 * nodes[b, 2] + w2 * nodes[c, 2]
    u0 = domain[k, 0]
    u1 = domain[k, 1]
    v0 = domain[k, 2]
    v1 = domain[k, 3]
    # start from the barycentric (u, v); where that fails (near poles and seams of
    # the parametrisation the blend of the nodes' (u, v) is poor) from each node
    ok = False
    singular = False
    n_edge = 0
    n_try = 0
    u = 0.0
    v = 0.0
    outside = min(w0, min(w1, w2)) < -1e-12
    for attempt in range(4):
        if attempt == 0:
            s0 = w0
            s1 = w1
            s2 = w2
            if outside:
                # paired by the margin: the extrapolated weights of a steep triangle at a
                # silhouette run wild (w = 1.4, -1.0 on the torus seen from the side);
                # start from the nearest point of the triangle instead
                s0 = max(w0, 0.0)
                s1 = max(w1, 0.0)
                s2 = max(w2, 0.0)
                sw = s0 + s1 + s2
                s0 /= sw
                s1 /= sw
                s2 /= sw
            us = s0 * uv[a, 0] + s1 * uv[b, 0] + s2 * uv[c, 0]
            vs = s0 * uv[a, 1] + s1 * uv[b, 1] + s2 * uv[c, 1]
        else:
            nd = tris[t, attempt - 1]
            us = uv[nd, 0]
            vs = uv[nd, 1]
        ok, u, v, at_edge, singular = _newton(deg, ncp, koff, poff, knots, cpw, k, us, vs, xg, yg,
                                              u0, u1, v0, v1, tol, max_iter, out)
        n_try += 1
        if ok:
            break
        if at_edge:
            n_edge += 1
        if attempt == 0 and (outside or not at_edge):
            # singular or slow, not a start problem: no restarts; nor for a point paired
            # by the margin, started from the triangle's nearest point (the restarts from
            # its nodes found nothing more on trj8's 0.2 M random points, and ran 87% of
            # the pair loop's time where edges carry a large tolerance)
            break
    edge = n_edge == n_try  # every start ran out of the domain: the point is off the face
    if ok:
        zn = out[0, 2]
        if outside:
            # outside its triangle (boundary margin): the extrapolated facet height means
            # little on a steep triangle, so check against the triangle's z range; but not
            # on a steep triangle by a silhouette (a fold seen from the side): there the
            # height moves fast along the fold (1.4 mm within 0.1 mm of xy on the torus
            # seen along -y), and the triangles over the fold itself are edge-on and pair
            # with nothing. Any exact solution inside the trimmed face is a point of the
            # surface, and the top-most candidate wins.
            za = nodes[a, 2]
            zb = nodes[b, 2]
            zc_ = nodes[c, 2]
            if not _wall_triangle(nodes, a, b, c) and (
                    zn < min(za, min(zb, zc_)) - face_zgap[k] or zn > max(za, max(zb, zc_)) + face_zgap[k]):
                ok = False
        elif abs(zn - zf) > face_zgap[k]:
            # another layer of a folded face; but on a steep triangle the facet height is
            # off by the mesh's xy error times the slope (0.1-0.3 mm on cornetta's 84-86
            # degree faces, where BRepMesh missed its 5 um deflection by 5x): there the
            # distance across the triangle's plane decides, within 10 deflections
            nz = _tri_nz(nodes, a, b, c)
            ok = nz < _WALL_NZ and abs(zn - zf) * nz <= 0.5 * face_zgap[k]
        if ok and tri_check[t] and face_bi[k, 1] > 0:
            if not point_in_bands(u, v, edges, band_ptr, band_edges, face_bi[k, 0], face_bi[k, 1],
                                  face_bf[k, 0], face_bf[k, 1], face_bf[k, 2]) and not in_tolerance(
                    u, v, out[0, 0], out[0, 1], out[0, 2], k, edges, band_ptr, band_edges, face_bi, face_bf):
                status[p] = 0  # outside the trimmed face (and its edges' tolerance)
                z[p] = np.nan
                return
    if ok:
        z[p] = out[0, 2]
        status[p] = 1
    elif mode == 0 and not edge and min(w0, min(w1, w2)) >= -1e-12 and not (singular and _wall_triangle(nodes, a, b, c)):
        # facet fallback (not for a point paired from outside its triangle by the boundary
        # margin, nor on a wall: see _wall_triangle); on a boundary triangle only where its
        # start is in the face
        if tri_check[t] and face_bi[k, 1] > 0:
            u = w0 * uv[a, 0] + w1 * uv[b, 0] + w2 * uv[c, 0]
            v = w0 * uv[a, 1] + w1 * uv[b, 1] + w2 * uv[c, 1]
            if not point_in_bands(u, v, edges, band_ptr, band_edges, face_bi[k, 0], face_bi[k, 1],
                                  face_bf[k, 0], face_bf[k, 1], face_bf[k, 2]) and not in_tolerance(
                    u, v, xg, yg, zf, k, edges, band_ptr, band_edges, face_bi, face_bf):
                z[p] = np.nan
                status[p] = 0
                return
        z[p] = zf
        status[p] = 2
    else:
        z[p] = np.nan
        status[p] = 0


@njit(cache=True, error_model="numpy", parallel=True)
def _solve_pairs(gidx, tri, w, nodes, uv, tris, tri_face, tri_check, face_mode, face_zgap,
                 deg, ncp, koff, poff, knots, cpw, domain, edges, band_ptr, band_edges, face_bi, face_bf,
                 px, py, x0, y0, dx, dy, ny, mode, tol, max_iter, z, status):
    """The pair loop of :func:`solve_pairs` (``ny > 0``: pair ``p`` at grid point
    ``gidx[p]`` of an ``ny``-column grid) and :func:`solve_pairs_xy` (``ny == 0``: at
    ``(px[gidx[p]], py[gidx[p]])``), in 64 blocks over the threads."""
    P = gidx.shape[0]
    nblk = 64
    for blk in prange(nblk):
        out = np.empty((3, 3))
        p0 = blk * P // nblk
        p1 = (blk + 1) * P // nblk
        for p in range(p0, p1):
            g = gidx[p]
            if ny > 0:
                xg = x0 + (g // ny) * dx
                yg = y0 + (g % ny) * dy
            else:
                xg = px[g]
                yg = py[g]
            if mode == 2 or face_mode[tri_face[tri[p]]] == 2:
                _facet_pair(p, tri, w, nodes, tris, z, status)
                continue
            _solve_one(p, xg, yg, tri, w, nodes, uv, tris, tri_face, tri_check, face_mode, face_zgap, deg, ncp,
                       koff, poff, knots, cpw, domain, edges, band_ptr, band_edges, face_bi, face_bf, mode, tol,
                       max_iter, z, status, out)


@njit(cache=True, error_model="numpy")
def solve_pairs(gidx, tri, w, nodes, uv, tris, tri_face, tri_check, face_mode, face_zgap,
                deg, ncp, koff, poff, knots, cpw, domain, edges, band_ptr, band_edges, face_bi, face_bf,
                x0, y0, dx, dy, ny, mode, tol, max_iter, z, status):
    """Height candidate of every pair, into ``z`` (P,) and ``status`` (P,) int8; pair ``p``
    is at grid point ``gidx[p]``, ``(x0 + (g // ny) * dx, y0 + (g % ny) * dy)``.

    Parameters
    ----------
    face_mode : (F,) int8
        1: invert the face's NURBS, 2: facets only (no surface or no uv).
    face_zgap : (F,) float64
        Largest accepted |z_newton - z_facet| (guards against a jump to another layer).
    tri_check : (M,) bool
        Triangle touches the mesh boundary: test the solution against the trim loops.
    edges, band_ptr, band_edges : trim loop edges in bands (:func:`point_in_bands`)
    face_bi : (F, 2) int64
        First band and number of bands of each face (0 bands: untrimmed).
    face_bf : (F, 3) float64
        ``vlo``, band height ``h`` and on-boundary tolerance ``eps`` of each face.
    mode : int
        0 auto (Newton, facet where it fails), 1 Newton only, 2 facets only.
    """
    none = np.empty(0)
    _solve_pairs(gidx, tri, w, nodes, uv, tris, tri_face, tri_check, face_mode, face_zgap, deg, ncp, koff, poff,
                 knots, cpw, domain, edges, band_ptr, band_edges, face_bi, face_bf, none,
                 none, x0, y0, dx, dy, max(ny, 1), mode, tol, max_iter, z, status)


@njit(cache=True, error_model="numpy")
def solve_pairs_xy(gidx, tri, w, nodes, uv, tris, tri_face, tri_check, face_mode, face_zgap,
                   deg, ncp, koff, poff, knots, cpw, domain, edges, band_ptr, band_edges, face_bi, face_bf,
                   px, py, mode, tol, max_iter, z, status):
    """:func:`solve_pairs` for scattered points: pair ``p`` is at ``(px[gidx[p]], py[gidx[p]])``."""
    _solve_pairs(gidx, tri, w, nodes, uv, tris, tri_face, tri_check, face_mode, face_zgap, deg, ncp, koff, poff,
                 knots, cpw, domain, edges, band_ptr, band_edges, face_bi, face_bf, px, py,
                 0.0, 0.0, 0.0, 0.0, 0, mode, tol, max_iter, z, status)


@njit(cache=True, error_model="numpy", parallel=True)
def count_pairs_xy(nodes, tris, tri_margin, px, py, bx0, by0, bh, nbx, nby, bin_ptr, bin_pts, counts):
    """Scattered points inside each triangle's xy projection, into ``counts`` (M,).

    The points are bucketed on a ``nbx`` x ``nby`` grid of square bins of side ``bh`` from
    ``(bx0, by0)``: bin ``(i, j)`` holds ``bin_pts[bin_ptr[i*nby + j]:bin_ptr[i*nby + j + 1]]``.
    """
    no_i = np.empty(0, dtype=np.int64)
    no_w = np.empty((0, 2))
    for t in prange(tris.shape[0]):
        counts[t] = _scan_tri(nodes, tris, tri_margin, t, px, py, bx0, by0, bh, nbx, nby, bin_ptr, bin_pts,
                              0, no_i, no_i, no_w, False)


@njit(cache=True, error_model="numpy", parallel=True)
def fill_pairs_xy(nodes, tris, tri_margin, t0, offsets, px, py, bx0, by0, bh, nbx, nby, bin_ptr, bin_pts,
                  gidx, tri, w):
    """:func:`fill_pairs` for scattered points (``gidx`` = point index), bins as :func:`count_pairs_xy`."""
    for tt in prange(offsets.shape[0] - 1):
        if offsets[tt + 1] == offsets[tt]:
            continue
        _scan_tri(nodes, tris, tri_margin, t0 + tt, px, py, bx0, by0, bh, nbx, nby, bin_ptr, bin_pts,
                  offsets[tt], gidx, tri, w, True)


@njit(cache=True, error_model="numpy", _nrt=False)
def _scan_tri(nodes, tris, tri_margin, t, px, py, bx0, by0, bh, nbx, nby, bin_ptr, bin_pts, p, gidx, tri, w, fill):
    """Count (``fill`` False) or write from ``p`` (``fill`` True) the points inside triangle ``t``."""
    ax, ay, bx, by, cx, cy, area = _tri_xy(nodes, tris, t)
    n = 0
    if area == 0.0:
        return 0  # vertical (or degenerate) in xy: covers no point
    inv = 1.0 / area
    mg = tri_margin[t]
    l0, l1, l2_ = _bary_limits(ax, ay, bx, by, cx, cy, area, mg)
    # the bins under the whole widened triangle: its acute corners reach beyond the box +
    # margin, and a point there must pair whatever the bins of the call (an answer may not
    # depend on the other points asked with it: tiles of a tiled conversion meet the map)
    xlo, xhi, ylo, yhi = _widened_box(ax, ay, bx, by, cx, cy, l0, l1, l2_)
    i0 = max(0, int(math.floor((xlo - bx0) / bh)))
    i1 = min(nbx - 1, int(math.floor((xhi - bx0) / bh)))
    j0 = max(0, int(math.floor((ylo - by0) / bh)))
    j1 = min(nby - 1, int(math.floor((yhi - by0) / bh)))
    for i in range(i0, i1 + 1):
        for j in range(j0, j1 + 1):
            q = i * nby + j
            for m in range(bin_ptr[q], bin_ptr[q + 1]):
                g = bin_pts[m]
                x = px[g]
                y = py[g]
                w1 = ((x - ax) * (cy - ay) - (cx - ax) * (y - ay)) * inv
                w2 = ((bx - ax) * (y - ay) - (x - ax) * (by - ay)) * inv
                if w1 >= l1 and w2 >= l2_ and 1.0 - w1 - w2 >= l0:
                    if fill:
                        gidx[p + n] = g
                        tri[p + n] = t
                        w[p + n, 0] = w1
                        w[p + n, 1] = w2
                    n += 1
    return n


@njit(cache=True, error_model="numpy")
def _widened_box(ax, ay, bx, by, cx, cy, l0, l1, l2):
    """xy box of the triangle widened to the barycentric limits ``(l0, l1, l2)`` (its corners
    are where two weights sit on their limits), with a 1e-9 mm rounding slack."""
    pax = (1.0 - l1 - l2) * ax + l1 * bx + l2 * cx
    pay = (1.0 - l1 - l2) * ay + l1 * by + l2 * cy
    pbx = l0 * ax + (1.0 - l0 - l2) * bx + l2 * cx
    pby = l0 * ay + (1.0 - l0 - l2) * by + l2 * cy
    pcx = l0 * ax + l1 * bx + (1.0 - l0 - l1) * cx
    pcy = l0 * ay + l1 * by + (1.0 - l0 - l1) * cy
    s = 1e-9
    return (min(pax, min(pbx, pcx)) - s, max(pax, max(pbx, pcx)) + s,
            min(pay, min(pby, pcy)) - s, max(pay, max(pby, pcy)) + s)


@njit(cache=True, error_model="numpy")
def _widened_window(ax, ay, bx, by, cx, cy, x0, y0, dx, dy, nx, ny, l0, l1, l2):
    """Grid index window ``(i0, i1, j0, j1)`` under the triangle widened to the barycentric
    limits (:func:`_widened_box`; a box + margin misses the acute corners' points)."""
    xmin, xmax, ymin, ymax = _widened_box(ax, ay, bx, by, cx, cy, l0, l1, l2)
    i0 = max(0, int(math.ceil((xmin - x0) / dx - 1e-9)))
    i1 = min(nx - 1, int(math.floor((xmax - x0) / dx + 1e-9)))
    j0 = max(0, int(math.ceil((ymin - y0) / dy - 1e-9)))
    j1 = min(ny - 1, int(math.floor((ymax - y0) / dy + 1e-9)))
    return i0, i1, j0, j1


@njit(cache=True, error_model="numpy")
def reduce_pairs(gidx, tri, tri_face, zc, status, zgrid, face, method):
    """Top-most candidate per grid point into the flat ``zgrid``, ``face``, ``method``."""
    for p in range(gidx.shape[0]):
        s = status[p]
        if s == 0:
            continue
        g = gidx[p]
        zp = zc[p]
        m = method[g]
        if m == 0 or zp > zgrid[g] or (zp == zgrid[g] and s < m):
            zgrid[g] = zp
            face[g] = tri_face[tri[p]]
            method[g] = s


# ---- distance to the B-rep (cad_io.distance) ---------------------------------------------------

@njit(cache=True, error_model="numpy", parallel=True)
def project_candidates(pts, cand_pt, cand_face, cand_uv, deg, ncp, koff, poff, knots, cpw, domain,
                       edges, band_ptr, band_edges, face_bi, face_bf, dist, inside):
    """Exact foot of point ``cand_pt[c]`` on face ``cand_face[c]`` from ``cand_uv[c]``.

    Levenberg-damped Gauss-Newton on the face's NURBS (``_nurbs_kernels._gauss_newton``);
    ``dist[c]`` is the distance to the foot, ``inside[c]`` whether the foot lies in the
    face's trim loops (always for an untrimmed face).
    """
    for c in prange(cand_pt.shape[0]):
        buf = np.empty((6, 3))
        dom = np.empty(4)
        k = cand_face[c]
        dom[0] = domain[k, 0]
        dom[1] = domain[k, 1]
        dom[2] = domain[k, 2]
        dom[3] = domain[k, 3]
        q = cand_pt[c]
        u, v, d = _gauss_newton(deg, ncp, koff, poff, knots, cpw, k, pts[q, 0], pts[q, 1], pts[q, 2],
                                cand_uv[c, 0], cand_uv[c, 1], dom, buf)
        dist[c] = d
        if face_bi[k, 1] > 0:
            inside[c] = point_in_bands(u, v, edges, band_ptr, band_edges, face_bi[k, 0], face_bi[k, 1],
                                       face_bf[k, 0], face_bf[k, 1], face_bf[k, 2])
        else:
            inside[c] = True


@njit(cache=True, error_model="numpy")
def _point_segment_d2(px, py, pz, ax, ay, az, bx, by, bz):
    """Squared distance from p to segment ab; a zero-length segment is its point."""
    ex = bx - ax
    ey = by - ay
    ez = bz - az
    ll = ex * ex + ey * ey + ez * ez
    t = 0.0
    if ll > 0.0:
        t = min(max(((px - ax) * ex + (py - ay) * ey + (pz - az) * ez) / ll, 0.0), 1.0)
    dx = px - (ax + t * ex)
    dy = py - (ay + t * ey)
    dz = pz - (az + t * ez)
    return dx * dx + dy * dy + dz * dz


#: a triangle whose squared doubled area is below this share of |ab|^2 |ac|^2 (sine of its
#: angle at a below 1e-8) is measured as its three edges: the closest-point regions' divisions
#: lose all meaning on such a needle, and on a zero-length edge they divide 0 by 0
_NEEDLE_SIN2 = 1e-16


@njit(cache=True, error_model="numpy")
def _point_triangle_d2(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz):
    """Squared distance from p to triangle abc (closest-point regions, Ericson 5.1.5).

    Degenerate triangles (a zero-length edge, three collinear or coincident vertices, as
    BRepMesh leaves on some real parts) are measured as their three edges; no division
    here can meet a zero.
    """
    abx = bx - ax
    aby = by - ay
    abz = bz - az
    acx = cx - ax
    acy = cy - ay
    acz = cz - az
    nx = aby * acz - abz * acy
    ny = abz * acx - abx * acz
    nz = abx * acy - aby * acx
    ab2 = abx * abx + aby * aby + abz * abz
    ac2 = acx * acx + acy * acy + acz * acz
    if not (nx * nx + ny * ny + nz * nz > _NEEDLE_SIN2 * ab2 * ac2):  # also NaN vertices
        d = _point_segment_d2(px, py, pz, ax, ay, az, bx, by, bz)
        d = min(d, _point_segment_d2(px, py, pz, bx, by, bz, cx, cy, cz))
        return min(d, _point_segment_d2(px, py, pz, cx, cy, cz, ax, ay, az))
    apx = px - ax
    apy = py - ay
    apz = pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    qx = ax
    qy = ay
    qz = az
    if d1 <= 0.0 and d2 <= 0.0:
        pass
    else:
        bpx = px - bx
        bpy = py - by
        bpz = pz - bz
        d3 = abx * bpx + aby * bpy + abz * bpz
        d4 = acx * bpx + acy * bpy + acz * bpz
        cpx = px - cx
        cpy = py - cy
        cpz = pz - cz
        d5 = abx * cpx + aby * cpy + abz * cpz
        d6 = acx * cpx + acy * cpy + acz * cpz
        vc = d1 * d4 - d3 * d2
        vb = d5 * d2 - d1 * d6
        va = d3 * d6 - d5 * d4
        if d3 >= 0.0 and d4 <= d3:
            qx = bx
            qy = by
            qz = bz
        elif d6 >= 0.0 and d5 <= d6:
            qx = cx
            qy = cy
            qz = cz
        elif vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
            return _point_segment_d2(px, py, pz, ax, ay, az, bx, by, bz)
        elif vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
            return _point_segment_d2(px, py, pz, ax, ay, az, cx, cy, cz)
        elif va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
            return _point_segment_d2(px, py, pz, bx, by, bz, cx, cy, cz)
        else:
            den = va + vb + vc
            if den > 0.0:
                sv = vb / den
                sw = vc / den
                qx = ax + abx * sv + acx * sw
                qy = ay + aby * sv + acy * sw
                qz = az + abz * sv + acz * sw
    ex = px - qx
    ey = py - qy
    ez = pz - qz
    return ex * ex + ey * ey + ez * ez


@njit(cache=True, error_model="numpy", parallel=True)
def mesh_distance(pts, cand_tri, nodes, tris, out):
    """Distance from each point to the nearest of its candidate triangles ``cand_tri`` (n, k)."""
    for q in prange(pts.shape[0]):
        best = np.inf
        for m in range(cand_tri.shape[1]):
            t = cand_tri[q, m]
            if t < 0:
                continue
            a = tris[t, 0]
            b = tris[t, 1]
            c = tris[t, 2]
            d2 = _point_triangle_d2(pts[q, 0], pts[q, 1], pts[q, 2], nodes[a, 0], nodes[a, 1], nodes[a, 2],
                                    nodes[b, 0], nodes[b, 1], nodes[b, 2], nodes[c, 0], nodes[c, 1], nodes[c, 2])
            best = min(best, d2)
        out[q] = math.sqrt(best)
