"""Numba kernels that prepare the visibility casting's blockers (:mod:`zmap.access.casting`):
the skin voxels' neighbour masks, voxels of one code merged into boxes, the merged runs'
extents and slabs, row hashes to group them, and the queries that block their own direction
(no validation, flat arrays only).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ._voxel_kernels import INTERIOR

__all__ = ["skin_masks", "merge_runs", "self_blocking", "run_members", "row_hash"]


@njit(cache=True)
def skin_masks(state, ijk, out):
    """Per skin voxel, a 27-bit mask of its interior neighbours: bit ``(dx+1)*9 + (dy+1)*3 + (dz+1)``
    is set where voxel (i+dx, j+dy, l+dz) is interior."""
    nx, ny, nz = state.shape
    for s in range(ijk.shape[0]):
        i, j, l = ijk[s, 0], ijk[s, 1], ijk[s, 2]
        m = np.int64(0)
        for dx in range(-1, 2):
            for dy in range(-1, 2):
                for dz in range(-1, 2):
                    a, b, c = i + dx, j + dy, l + dz
                    if 0 <= a < nx and 0 <= b < ny and 0 <= c < nz and state[a, b, c] == INTERIOR:
                        m |= np.int64(1) << np.int64((dx + 1) * 9 + (dy + 1) * 3 + (dz + 1))
        out[s] = m


@njit(cache=True)
def merge_runs(code, out):
    """Greedy boxes of equal codes: every voxel with ``code > 0`` lies in exactly one box of
    voxels that all hold its code. Boxes grow along the last axis first, then the middle,
    then the first (the voxels' order of :func:`numpy.argwhere`). ``out`` (n, 7) gets rows
    ``(i0, j0, l0, i1, j1, l1, code)`` (inclusive ends); returns the number of boxes.

    The skin cubes of a face's layer share their neighbour mask, so they merge into a few
    boxes: a line meets the union of the cubes exactly where it meets the box, and leaves it
    at the largest of their exits, so a depth buffer drawn from the boxes holds the values
    drawn from the cubes, for a fraction of the cells visited."""
    ni, nj, nl = code.shape
    used = np.zeros(code.shape, dtype=np.uint8)
    nb = 0
    for i in range(ni):
        for j in range(nj):
            for l in range(nl):
                c = code[i, j, l]
                if c <= 0 or used[i, j, l]:
                    continue
                l1 = l
                while l1 + 1 < nl and code[i, j, l1 + 1] == c and not used[i, j, l1 + 1]:
                    l1 += 1
                j1 = j
                while j1 + 1 < nj:
                    ok = True
                    for ll in range(l, l1 + 1):
                        if code[i, j1 + 1, ll] != c or used[i, j1 + 1, ll]:
                            ok = False
                            break
                    if not ok:
                        break
                    j1 += 1
                i1 = i
                while i1 + 1 < ni:
                    ok = True
                    for jj in range(j, j1 + 1):
                        for ll in range(l, l1 + 1):
                            if code[i1 + 1, jj, ll] != c or used[i1 + 1, jj, ll]:
                                ok = False
                                break
                        if not ok:
                            break
                    if not ok:
                        break
                    i1 += 1
                used[i:i1 + 1, j:j1 + 1, l:l1 + 1] = 1
                out[nb, 0], out[nb, 1], out[nb, 2] = i, j, l
                out[nb, 3], out[nb, 4], out[nb, 5] = i1, j1, l1
                out[nb, 6] = c
                nb += 1
    return nb


@njit(cache=True)
def self_blocking(vl, light, opp, out):
    """out[m] = 1 where some direction i is in vl[m] and opp[i] in light[m] (bitsets)."""
    k = opp.shape[0]
    for m in range(vl.shape[0]):
        out[m] = 0
        for i in range(k):
            if (vl[m, i >> 6] >> np.uint64(i & 63)) & np.uint64(1):
                o = opp[i]
                if (light[m, o >> 6] >> np.uint64(o & 63)) & np.uint64(1):
                    out[m] = 1
                    break


@njit(cache=True)
def run_members(runs, first, ax, lo, hi, offset, slab, mlo, mhi, mslab):
    """Per run of :func:`merge_runs` over blockers (``first``: the blocker of each voxel):
    the union of its members' extents along their axis, and the slab that reaches as low as
    the lowest of theirs, measured from the plane offset of the run's first member."""
    for r in range(runs.shape[0]):
        a = ax[first[runs[r, 0], runs[r, 1], runs[r, 2]]]
        ref = offset[first[runs[r, 0], runs[r, 1], runs[r, 2]]]
        lo_ = 1.0e300
        hi_ = -1.0e300
        low = 1.0e300
        for i in range(runs[r, 0], runs[r, 3] + 1):
            for j in range(runs[r, 1], runs[r, 4] + 1):
                for l in range(runs[r, 2], runs[r, 5] + 1):
                    m = first[i, j, l]
                    lo_ = min(lo_, lo[m, a])
                    hi_ = max(hi_, hi[m, a])
                    low = min(low, offset[m] - slab[m])
        mlo[r, a] = lo_
        mhi[r, a] = hi_
        mslab[r] = ref - low


@njit(cache=True)
def row_hash(key, out):
    """out[r] = a 64-bit FNV-1a hash of row r of ``key`` (int64): rows equal, hashes equal."""
    for r in range(key.shape[0]):
        h = np.uint64(14695981039346656037)
        for c in range(key.shape[1]):
            x = np.uint64(key[r, c])
            for b in range(8):
                h ^= (x >> np.uint64(8 * b)) & np.uint64(255)
                h *= np.uint64(1099511628211)
        out[r] = h
