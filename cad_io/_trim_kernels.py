"""Numba kernels of the trim test: whether a face's (u, v) lies inside its trim loops, or on
the face within the tolerance of its edges as OCC's ray cast counts it; no validation here.

The loops come as polygons (:func:`point_in_loops`, :func:`points_in_loops`) or, for the
sampler's pair loop, as edges bucketed in bands of v (:func:`point_in_bands`,
:func:`in_tolerance`; :mod:`cad_io._sample_trim` builds those arrays). Callers: the pair
solver (:mod:`cad_io._sample_kernels`), the distance kernels
(:mod:`cad_io._distance_kernels`) and :func:`cad_io.mesh.trimmed_grid_mesh`. The helpers
on the per-pair path run with ``_nrt=False`` (see :mod:`cad_io._sample_kernels`).
"""

from __future__ import annotations

import math

from numba import njit, prange

__all__ = ["in_tolerance", "point_in_bands", "point_in_loops", "points_in_loops"]


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
