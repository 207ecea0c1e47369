"""Numba kernels over direction bitsets (rows of uint64 words, bit i of word i >> 6 for
direction i): columns packed into bitsets, per-direction lists of the rows that hold a bit,
bitsets dilated over neighbouring voxels and the greedy set cover of the set-ups (no
validation, flat arrays only).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

__all__ = ["pack_columns", "bit_lists", "dilate_bits", "greedy_cover"]


@njit(cache=True, parallel=True)
def pack_columns(out, bits):
    """bits[m] (words) = the bitset of column m of ``out`` (k, mb) uint8 (bit i: out[i, m] != 0):
    blocks of 64 columns per thread, each reading its stretch of every row."""
    k, m = out.shape
    for bl in prange((m + 63) // 64):
        m0 = bl * 64
        m1 = min(m, m0 + 64)
        for mm in range(m0, m1):
            for w in range(bits.shape[1]):
                bits[mm, w] = np.uint64(0)
        for i in range(k):
            w = i >> 6
            bit = np.uint64(1) << np.uint64(i & 63)
            for mm in range(m0, m1):
                if out[i, mm]:
                    bits[mm, w] |= bit


@njit(cache=True)
def bit_lists(bits, k, ptr, idx):
    """Per direction i < k, the rows of ``bits`` (rows, words) with bit i set, as CSR:
    ``idx[ptr[i]:ptr[i + 1]]`` (``ptr`` (k + 1); ``idx`` as long as the bits set)."""
    n = bits.shape[0]
    for i in range(k + 1):
        ptr[i] = 0
    for r in range(n):
        for i in range(k):
            if (bits[r, i >> 6] >> np.uint64(i & 63)) & np.uint64(1):
                ptr[i + 1] += 1
    for i in range(k):
        ptr[i + 1] += ptr[i]
    fill = ptr[:k].copy()
    for r in range(n):
        for i in range(k):
            if (bits[r, i >> 6] >> np.uint64(i & 63)) & np.uint64(1):
                idx[fill[i]] = r
                fill[i] += 1


@njit(cache=True, parallel=True)
def dilate_bits(index, ijk, bits, rad, out):
    """out[b] = OR of bits[w] over the boundary voxels w within ``rad`` voxels of b along each
    axis (b itself included): the directions some voxel near b keeps."""
    nx, ny, nz = index.shape
    W = bits.shape[1]
    for b in prange(ijk.shape[0]):
        for w in range(W):
            out[b, w] = np.uint64(0)
        i0, j0, l0 = ijk[b, 0], ijk[b, 1], ijk[b, 2]
        for i in range(max(0, i0 - rad), min(nx, i0 + rad + 1)):
            for j in range(max(0, j0 - rad), min(ny, j0 + rad + 1)):
                for l in range(max(0, l0 - rad), min(nz, l0 + rad + 1)):
                    m = index[i, j, l]
                    if m >= 0:
                        for w in range(W):
                            out[b, w] |= bits[m, w]


@njit(cache=True)
def greedy_cover(amap, area, cand, max_setups, chosen, gains):
    """Greedy set cover by area over bitsets: gains kept up to date by subtracting the voxels
    each choice covers. Returns the number chosen; ``chosen[s]`` the direction of set-up s and
    ``gains[s]`` the area it newly covered."""
    mb, W = amap.shape
    k = cand.shape[0]
    gain = np.zeros(k)
    left = np.zeros(mb, dtype=np.uint8)
    for b in range(mb):
        for i in range(k):
            if cand[i] and (amap[b, i >> 6] >> np.uint64(i & 63)) & np.uint64(1):
                gain[i] += area[b]
                left[b] = 1
    n = 0
    while n < max_setups:
        j = -1
        best = 0.0
        for i in range(k):
            if gain[i] > best:
                best = gain[i]
                j = i
        if j < 0:
            break
        chosen[n] = j
        gains[n] = best
        n += 1
        for b in range(mb):
            if left[b] and (amap[b, j >> 6] >> np.uint64(j & 63)) & np.uint64(1):
                left[b] = 0
                for i in range(k):
                    if cand[i] and (amap[b, i >> 6] >> np.uint64(i & 63)) & np.uint64(1):
                        gain[i] -= area[b]
        gain[j] = 0.0
    return n
