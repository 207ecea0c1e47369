"""Numba kernels that check a mesh of :mod:`zmap.mesh.decimate` against its map: the largest
vertical error over the nodes and, per point, the faces whose shadow holds it (cracks and
overlaps) (no validation, flat arrays only).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["measure_kernel", "cover_counts"]


@njit(cache=True)
def measure_kernel(z, vi, vj, faces, vz):
    """Max over nodes of |mesh height - z| (exact integer barycentrics); a node that is a
    vertex of its triangle counts its vertex height. NaN nodes inside a face give inf."""
    worst = 0.0
    for f in range(faces.shape[0]):
        a = faces[f, 0]
        b = faces[f, 1]
        c = faces[f, 2]
        ax = vi[a]
        ay = vj[a]
        bx = vi[b]
        by = vj[b]
        cx = vi[c]
        cy = vj[c]
        area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
        if area == 0:
            continue
        for x in range(min(ax, bx, cx), max(ax, bx, cx) + 1):
            for y in range(min(ay, by, cy), max(ay, by, cy) + 1):
                wa = (bx - x) * (cy - y) - (by - y) * (cx - x)
                wb = (cx - x) * (ay - y) - (cy - y) * (ax - x)
                wc = (ax - x) * (by - y) - (ay - y) * (bx - x)
                if area > 0:
                    if wa < 0 or wb < 0 or wc < 0:
                        continue
                else:
                    if wa > 0 or wb > 0 or wc > 0:
                        continue
                h = z[x, y]
                if np.isnan(h):
                    return np.inf
                if wb == 0 and wc == 0:
                    m = vz[a]
                elif wa == 0 and wc == 0:
                    m = vz[b]
                elif wa == 0 and wb == 0:
                    m = vz[c]
                else:
                    m = (wa * vz[a] + wb * vz[b] + wc * vz[c]) / area
                d = abs(m - h)
                if d > worst:
                    worst = d
    return worst


@njit(cache=True)
def cover_counts(vi, vj, faces, px, py, ny1, cell_off, cell_pts, count):
    """count[p] = number of faces whose xy shadow holds point p (node units); the points are
    bucketed by cell (cell = floor(px) * ny1 + floor(py), CSR ``cell_off``/``cell_pts``)."""
    ncell = cell_off.shape[0] - 1
    nx1 = ncell // ny1
    for f in range(faces.shape[0]):
        a = faces[f, 0]
        b = faces[f, 1]
        c = faces[f, 2]
        ax = float(vi[a])
        ay = float(vj[a])
        bx = float(vi[b])
        by = float(vj[b])
        cx = float(vi[c])
        cy = float(vj[c])
        area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
        if area == 0:
            continue
        for ci in range(int(min(ax, bx, cx)), min(int(max(ax, bx, cx)), nx1)):
            for cj in range(int(min(ay, by, cy)), min(int(max(ay, by, cy)), ny1)):
                cell = ci * ny1 + cj
                for k in range(cell_off[cell], cell_off[cell + 1]):
                    p = cell_pts[k]
                    x = px[p]
                    y = py[p]
                    wa = (bx - x) * (cy - y) - (by - y) * (cx - x)
                    wb = (cx - x) * (ay - y) - (cy - y) * (ax - x)
                    wc = (ax - x) * (by - y) - (ay - y) * (bx - x)
                    if area > 0:
                        if wa >= 0 and wb >= 0 and wc >= 0:
                            count[p] += 1
                    elif wa <= 0 and wb <= 0 and wc <= 0:
                        count[p] += 1
