"""Numba kernels that mesh one region of :mod:`zmap.mesh.decimate` without the greedy
refinement alone: in full (two triangles per valid cell) and, for a region that holds NaN
nodes, in tiles (those with a NaN node in full, the others refined) (no validation, flat
arrays only).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ._polyline_kernels import _side, refine_line
from ._refine_kernels import refine_kernel

__all__ = ["DENSE_TILE", "full_kernel", "dense_kernel"]

# tiles of a region that holds NaN nodes (:func:`dense_kernel`), in cells
DENSE_TILE = 8


@njit(cache=True)
def full_kernel(z, i0, j0, W, H, vout, tout):
    """Two counter-clockwise triangles per cell whose four corners are finite; vertices are
    the nodes those cells use (local offsets x*H + y). Returns (n_vertices, n_triangles)."""
    ids = np.full(W * H, -1, dtype=np.int64)
    nv = 0
    nt = 0
    for x in range(W - 1):
        for y in range(H - 1):
            if (np.isnan(z[i0 + x, j0 + y]) or np.isnan(z[i0 + x + 1, j0 + y])
                    or np.isnan(z[i0 + x + 1, j0 + y + 1]) or np.isnan(z[i0 + x, j0 + y + 1])):
                continue
            a = x * H + y
            b = (x + 1) * H + y
            c = (x + 1) * H + y + 1
            d = x * H + y + 1
            for o in (a, b, c, d):
                if ids[o] < 0:
                    ids[o] = nv
                    vout[nv] = o
                    nv += 1
            tout[nt, 0] = ids[a]
            tout[nt, 1] = ids[b]
            tout[nt, 2] = ids[c]
            tout[nt + 1, 0] = ids[a]
            tout[nt + 1, 1] = ids[c]
            tout[nt + 1, 2] = ids[d]
            nt += 2
    return nv, nt


@njit(cache=True)
def _box_has_nan(z, i0, j0, i1, j1):
    for i in range(i0, i1 + 1):
        for j in range(j0, j1 + 1):
            if np.isnan(z[i, j]):
                return True
    return False


@njit(cache=True)
def _tile_row_sides(z, i0, j0, W, H, tol, tile, nan, keep, h):
    """Border vertices on the tile rows i = a*tile of the region z[i0:i0+W, j0:j0+H]: every
    node on the region's own sides and next to a NaN tile, a refined polyline between two
    tiles without NaN. :func:`dense_kernel` calls it on the transposed map for the columns."""
    ntx, nty = nan.shape
    for la in range(ntx + 1):
        i = min(la * tile, W - 1)
        for b in range(nty):
            jb0 = b * tile
            jb1 = min(jb0 + tile, H - 1)
            n = jb1 - jb0 + 1
            if la == 0 or la == ntx or nan[la - 1, b] or nan[la, b]:
                for m in range(n):
                    keep[la, jb0 + m] = True
            else:
                for m in range(n):
                    h[m] = z[i0 + i, j0 + jb0 + m]
                refine_line(h[:n], tol, keep[la, jb0:jb1 + 1])


@njit(cache=True)
def dense_kernel(z, i0, j0, W, H, tol, tile, vout, tout):
    """A region that holds NaN nodes: split into tiles of ``tile`` cells; tiles with a NaN node
    are meshed in full (two triangles per valid cell), the others refined to ``tol`` like a
    region, with the sides between two such tiles refined as shared polylines and every other
    side (the region's own sides, sides next to a NaN tile) keeping every node, so the region
    meets its neighbours (which keep every node on a side shared with it) without cracks.
    Returns (n_vertices, n_triangles) as :func:`full_kernel`, or (-1, -1) on overflow."""
    ntx = (W - 2) // tile + 1
    nty = (H - 2) // tile + 1
    nan = np.zeros((ntx, nty), dtype=np.bool_)
    for a in range(ntx):
        for b in range(nty):
            nan[a, b] = _box_has_nan(z, i0 + a * tile, j0 + b * tile, i0 + min((a + 1) * tile, W - 1),
                                     j0 + min((b + 1) * tile, H - 1))
    # border vertices of the tile sides: rows i = a*tile (local) and columns j = b*tile
    keep_i = np.zeros((ntx + 1, H), dtype=np.bool_)
    keep_j = np.zeros((nty + 1, W), dtype=np.bool_)
    h = np.empty(tile + 1, dtype=np.float64)
    _tile_row_sides(z, i0, j0, W, H, tol, tile, nan, keep_i, h)
    # the columns are the rows of the transposed map
    _tile_row_sides(z.T, j0, i0, H, W, tol, tile, nan.T, keep_j, h)
    ids = np.full(W * H, -1, dtype=np.int64)
    tv = np.empty((tile + 1) * (tile + 1), dtype=np.int64)
    tt = np.empty((2 * tile * tile, 3), dtype=np.int32)
    empty = np.zeros(0, dtype=np.int32)
    nv = 0
    nt = 0
    for a in range(ntx):
        for b in range(nty):
            ia0 = a * tile
            jb0 = b * tile
            ia1 = min(ia0 + tile, W - 1)
            jb1 = min(jb0 + tile, H - 1)
            Wt = ia1 - ia0 + 1
            Ht = jb1 - jb0 + 1
            if nan[a, b]:
                cv, ct = full_kernel(z, i0 + ia0, j0 + jb0, Wt, Ht, tv, tt)
            else:
                s0 = _side(keep_i[a, jb0:jb1 + 1], Ht)
                s1 = _side(keep_j[b + 1, ia0:ia1 + 1], Wt)
                s2 = _side(keep_i[a + 1, jb0:jb1 + 1], Ht)
                s3 = _side(keep_j[b, ia0:ia1 + 1], Wt)
                cv, ct = refine_kernel(z, i0 + ia0, j0 + jb0, Wt, Ht, tol, s0, s1, s2, s3, tv, tt, empty, empty)
                if cv < 0:
                    return -1, -1
            for t in range(ct):
                for c in range(3):
                    o = tv[tt[t, c]]
                    x = o // Ht
                    g = (ia0 + x) * H + jb0 + (o - x * Ht)
                    if ids[g] < 0:
                        ids[g] = nv
                        vout[nv] = g
                        nv += 1
                    tout[nt, c] = ids[g]
                nt += 1
    return nv, nt
