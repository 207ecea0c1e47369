"""Numba kernels of the z-map sampler (:mod:`cad_io.sampler`); no validation here.

The sampler works on *pairs* (grid point, mesh triangle that covers it in xy): every pair
is one candidate height. :func:`count_pairs` and :func:`fill_pairs` rasterise the
triangles onto the grid (barycentric weights of the grid point in the triangle),
:func:`solve_pairs` turns each pair into a height (2D Jacobian inversion on the face's
NURBS from the barycentric (u, v), or the triangle's exact barycentric height), and
:func:`reduce_pairs` keeps the top-most candidate per grid point.

The Newton iteration on a face's NURBS is :mod:`cad_io._newton_kernels`, the trim test
:mod:`cad_io._trim_kernels`.

Status codes (the ``method`` layer): 0 no height, 1 Jacobian inversion, 2 facet.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

# mesh_distance, project_candidates and points_in_loops are re-exported: cad_io.distance and
# cad_io.mesh import them from here
from ._distance_kernels import mesh_distance, project_candidates
from ._newton_kernels import _newton
from ._trim_kernels import in_tolerance, point_in_bands, points_in_loops

__all__ = ["count_pairs", "count_pairs_xy", "fill_pairs", "fill_pairs_xy", "mesh_distance", "points_in_loops",
           "project_candidates", "reduce_pairs", "solve_pairs", "solve_pairs_xy"]

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
