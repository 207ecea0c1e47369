"""Numba kernels of :mod:`cad_io.distance`: exact feet of points on the packed NURBS faces
(:func:`project_candidates`) and distances to mesh triangles (:func:`mesh_distance`); no
validation here.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ._nurbs_kernels import _gauss_newton
from ._trim_kernels import point_in_bands

__all__ = ["mesh_distance", "project_candidates"]


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
