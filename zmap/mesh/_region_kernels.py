"""Numba kernels of :mod:`zmap.mesh.decimate` over a whole map of regions: the regions that
hold NaN nodes or changed, their shared sides' border vertices, the regions meshed into
pools, and the pools assembled into one mesh (no validation, flat arrays only).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ._polyline_kernels import _line_side, _side
from ._refine_kernels import refine_kernel, refine_more_kernel
from ._tile_kernels import DENSE_TILE, dense_kernel, full_kernel

__all__ = ["region_has_nan", "changed_regions", "remesh_regions", "rays_to_regions", "assemble", "changed_boxes"]


@njit(cache=True)
def _region_box(bi, bj, r, nx, ny):
    """First and last node (i0, j0, i1, j1) of region (bi, bj), its borders included."""
    i0 = bi * r
    j0 = bj * r
    return i0, j0, min(i0 + r, nx - 1), min(j0 + r, ny - 1)


@njit(cache=True)
def region_has_nan(z, r, todo, out):
    """out[bi, bj] = region (bi, bj) of ``todo`` holds a NaN node (borders included)."""
    nx, ny = z.shape
    for k in range(todo.shape[0]):
        bi = todo[k, 0]
        bj = todo[k, 1]
        i0, j0, i1, j1 = _region_box(bi, bj, r, nx, ny)
        f = False
        for i in range(i0, i1 + 1):
            for j in range(j0, j1 + 1):
                if np.isnan(z[i, j]):
                    f = True
                    break
            if f:
                break
        out[bi, bj] = f


@njit(cache=True)
def _mark_regions(i, j, r, nrx, nry, hit):
    """hit[bi, bj] = True for every region whose nodes (its borders included) hold node (i, j)."""
    bi_lo = (i - 1) // r if i > 0 else 0
    bi_hi = min(i // r, nrx - 1)
    bj_lo = (j - 1) // r if j > 0 else 0
    bj_hi = min(j // r, nry - 1)
    for bi in range(bi_lo, bi_hi + 1):
        for bj in range(bj_lo, bj_hi + 1):
            hit[bi, bj] = True


@njit(cache=True)
def changed_regions(a, b, r, nrx, nry, hit):
    """hit[bi, bj] |= some node of region (bi, bj) (borders included) differs between a and b."""
    nx, ny = a.shape
    for i in range(nx):
        for j in range(ny):
            u = a[i, j]
            v = b[i, j]
            if u == v or (np.isnan(u) and np.isnan(v)):
                continue
            _mark_regions(i, j, r, nrx, nry, hit)


@njit(cache=True)
def _sides(z, r, tol, dense, todo, mode, keep_i, keep_j):
    """Border vertices of every side of the regions in ``todo``, each side once.

    ``keep_i[li, j]``: node j of the grid row i = min(li*r, nx-1) is a border vertex;
    ``keep_j[lj, i]``: node i of the grid column j = min(lj*r, ny-1)."""
    nx, ny = z.shape
    nrx, nry = dense.shape
    done_i = np.zeros((nrx + 1, nry), dtype=np.bool_)
    done_j = np.zeros((nry + 1, nrx), dtype=np.bool_)
    h = np.empty(r + 1, dtype=np.float64)
    tmp = np.empty(r + 1, dtype=np.bool_)
    for k in range(todo.shape[0]):
        bi = todo[k, 0]
        bj = todo[k, 1]
        _row_sides(z, r, tol, dense, mode, keep_i, done_i, bi, bj, h, tmp)
        # the columns are the rows of the transposed map
        _row_sides(z.T, r, tol, dense.T, mode.T, keep_j, done_j, bj, bi, h, tmp)


@njit(cache=True)
def _row_sides(z, r, tol, dense, mode, keep, done, bi, bj, h, tmp):
    """The two grid rows i0 and i1 of region (bi, bj), each between regions (li-1, bj) and
    (li, bj), unless ``done``; :func:`_sides` calls it on the transposed map for the columns."""
    nx, ny = z.shape
    nrx = dense.shape[0]
    i0, j0, i1, j1 = _region_box(bi, bj, r, nx, ny)
    for li in (bi, bi + 1):
        if done[li, bj]:
            continue
        done[li, bj] = True
        i = min(li * r, nx - 1)
        any_dense = False
        all_fresh = True
        for a in (li - 1, li):
            if a >= 0 and a < nrx:
                any_dense |= dense[a, bj]
                all_fresh &= mode[a, bj] == 1
        n = j1 - j0 + 1
        for m in range(n):
            h[m] = z[i, j0 + m]
        _line_side(h[:n], tol, keep[li, j0:j1 + 1], tmp, any_dense, all_fresh)


@njit(cache=True)
def remesh_regions(z, r, tol, full, dense, todo, mode, vpool, tpool, nv, nt, keep_i, keep_j,
                   ktri, khe, has, cbox):
    """Mesh the regions listed in ``todo`` (pairs bi, bj) into the pools.

    A region is meshed in full (two triangles per valid cell) when ``full`` is set; a
    ``dense`` one (it holds a NaN node) by :func:`dense_kernel` (in full only in its tiles
    that hold a NaN node), and a border side shared with a dense region keeps every node. Otherwise the sides are refined as polylines to ``tol`` (:func:`_sides`: one
    answer per side, shared by both its regions) and the interior by
    :func:`refine_kernel` (``mode`` 1: afresh) or :func:`refine_more_kernel` (``mode`` 2, a
    region with a kept triangulation, ``has``: incrementally, over the changed nodes'
    box ``cbox[bi, bj]`` = global i0, j0, i1, j1). ``ktri``/``khe`` (regions, 3 * room)
    keep each region's triangulation when they are non-empty. Returns the number of regions
    whose work arrays overflowed (meshed in full instead).
    """
    nx, ny = z.shape
    nrx, nry = dense.shape
    keeping = ktri.shape[0] > 0
    empty = np.zeros(0, dtype=np.int32)
    if not full:
        _sides(z, r, tol, dense, todo, mode, keep_i, keep_j)
    bad = 0
    for k in range(todo.shape[0]):
        bi = todo[k, 0]
        bj = todo[k, 1]
        reg = bi * nry + bj
        i0, j0, i1, j1 = _region_box(bi, bj, r, nx, ny)
        W = i1 - i0 + 1
        H = j1 - j0 + 1
        if full or dense[bi, bj]:
            a = -1
            if not full:
                a, b = dense_kernel(z, i0, j0, W, H, tol, DENSE_TILE, vpool[reg], tpool[reg])
            if a < 0:
                a, b = full_kernel(z, i0, j0, W, H, vpool[reg], tpool[reg])
            nv[reg] = a
            nt[reg] = b
            has[reg] = False
            continue
        # side i=0 (shared with region bi-1), j=H-1 (bj+1), i=W-1 (bi+1), j=0 (bj-1)
        s0 = _side(keep_i[bi, j0:j1 + 1], H)
        s1 = _side(keep_j[bj + 1, i0:i1 + 1], W)
        s2 = _side(keep_i[bi + 1, j0:j1 + 1], H)
        s3 = _side(keep_j[bj, i0:i1 + 1], W)
        kt = ktri[reg] if keeping else empty
        kh = khe[reg] if keeping else empty
        if keeping and mode[bi, bj] == 2 and has[reg]:
            a, b = refine_more_kernel(z, i0, j0, W, H, tol, s0, s1, s2, s3, vpool[reg], tpool[reg],
                                      kt, kh, nv[reg], nt[reg], cbox[bi, bj, 0] - i0,
                                      cbox[bi, bj, 1] - j0, cbox[bi, bj, 2] - i0, cbox[bi, bj, 3] - j0)
        else:
            a, b = refine_kernel(z, i0, j0, W, H, tol, s0, s1, s2, s3, vpool[reg], tpool[reg], kt, kh)
        has[reg] = keeping and a >= 0
        if a < 0:
            bad += 1
            a, b = full_kernel(z, i0, j0, W, H, vpool[reg], tpool[reg])
        nv[reg] = a
        nt[reg] = b
    return bad


@njit(cache=True)
def rays_to_regions(rays, ny, r, nrx, nry, hit):
    """hit[bi, bj] = True for every region whose nodes (borders included) hold one of ``rays``
    (ray = i*ny + j)."""
    for k in range(rays.shape[0]):
        i = rays[k] // ny
        j = rays[k] - i * ny
        _mark_regions(i, j, r, nrx, nry, hit)


@njit(cache=True)
def assemble(vpool, tpool, nv, nt, r, nry, nx, ny, ids):
    """Global mesh of all regions: vertex node ids (i*ny + j) and faces. ``ids`` (nx*ny,
    int32) is scratch, returned filled with -1."""
    nreg = nv.shape[0]
    tv = 0
    tt = 0
    for reg in range(nreg):
        tv += nv[reg]
        tt += nt[reg]
    nodes = np.empty(tv, dtype=np.int64)
    faces = np.empty((tt, 3), dtype=np.int32)
    local = np.empty(vpool.shape[1], dtype=np.int32)
    n = 0
    f = 0
    for reg in range(nreg):
        bi = reg // nry
        bj = reg - bi * nry
        i0, j0, _, j1 = _region_box(bi, bj, r, nx, ny)
        H = j1 - j0 + 1
        for v in range(nv[reg]):
            o = vpool[reg, v]
            x = o // H
            g = (i0 + x) * ny + j0 + (o - x * H)
            if ids[g] < 0:
                ids[g] = n
                nodes[n] = g
                n += 1
            local[v] = ids[g]
        for t in range(nt[reg]):
            faces[f, 0] = local[tpool[reg, t, 0]]
            faces[f, 1] = local[tpool[reg, t, 1]]
            faces[f, 2] = local[tpool[reg, t, 2]]
            f += 1
    for k in range(n):
        ids[nodes[k]] = -1
    return nodes[:n], faces


@njit(cache=True)
def changed_boxes(a, b, r, hit, box):
    """For every region marked in ``hit``: the box of its nodes (borders included) that
    differ between ``a`` and ``b`` (NaN equal to NaN) into ``box[bi, bj]`` (i0, j0, i1, j1);
    ``hit`` cleared where none does (history events below the top surface)."""
    nx, ny = a.shape
    nrx, nry = hit.shape
    for bi in range(nrx):
        for bj in range(nry):
            if not hit[bi, bj]:
                continue
            i0, j0, i1, j1 = _region_box(bi, bj, r, nx, ny)
            lo_i = i1 + 1
            lo_j = j1 + 1
            hi_i = -1
            hi_j = -1
            for i in range(i0, i1 + 1):
                for j in range(j0, j1 + 1):
                    u = a[i, j]
                    v = b[i, j]
                    if u != v and not (np.isnan(u) and np.isnan(v)):
                        lo_i = min(lo_i, i)
                        hi_i = max(hi_i, i)
                        lo_j = min(lo_j, j)
                        hi_j = max(hi_j, j)
            if hi_i < 0:
                hit[bi, bj] = False
            else:
                box[bi, bj, 0] = lo_i
                box[bi, bj, 1] = lo_j
                box[bi, bj, 2] = hi_i
                box[bi, bj, 3] = hi_j
