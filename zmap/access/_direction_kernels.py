"""Numba kernels of :mod:`zmap.access.directions` (no validation, flat arrays only)."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

__all__ = ["lookup_kernel", "popcount_rows", "bits_to_bool", "bool_to_bits", "above_words", "above_bits"]


@njit(cache=True)
def lookup_one(nx, ny, nz, centres, frames, q):
    """Tessel index of the direction (nx, ny, nz) (need not be unit).

    ``centres`` (20, 3): unit centres of the icosahedron's faces; ``frames`` (20, 3, 3): per
    face the rows A, B - A, C - A of its flat triangle (A, B, C its corners on the unit sphere).
    The face is the one whose centre is nearest (the spherical triangles of a regular
    polyhedron are the Voronoi cells of its face centres); inside it, the flat barycentric
    coordinates of the ray's hit with the face's plane pick the sub-triangle.
    """
    best = -1.0e300
    f = 0
    for i in range(20):
        s = nx * centres[i, 0] + ny * centres[i, 1] + nz * centres[i, 2]
        if s > best:
            best = s
            f = i
    if not best > 0.0:  # the zero vector or NaN: no tessel (and no division by zero below)
        return -1
    ax, ay, az = frames[f, 0, 0], frames[f, 0, 1], frames[f, 0, 2]
    ux, uy, uz = frames[f, 1, 0], frames[f, 1, 1], frames[f, 1, 2]
    vx, vy, vz = frames[f, 2, 0], frames[f, 2, 1], frames[f, 2, 2]
    # plane through A with normal c: hit point t * n with t = (A.c) / (n.c)
    cx, cy, cz = centres[f, 0], centres[f, 1], centres[f, 2]
    t = (ax * cx + ay * cy + az * cz) / best
    px, py, pz = t * nx - ax, t * ny - ay, t * nz - az
    # solve p = b * U + c * V in the plane (least squares through the 2x2 Gram system)
    uu = ux * ux + uy * uy + uz * uz
    uv = ux * vx + uy * vy + uz * vz
    vv = vx * vx + vy * vy + vz * vz
    pu = px * ux + py * uy + pz * uz
    pv = px * vx + py * vy + pz * vz
    det = uu * vv - uv * uv
    b = (pu * vv - pv * uv) / det
    c = (pv * uu - pu * uv) / det
    fb = b * q
    fc = c * q
    i = int(np.floor(fb))
    j = int(np.floor(fc))
    if i < 0:
        i = 0
    if j < 0:
        j = 0
    if i > q - 1:
        i = q - 1
    if j > q - 1:
        j = q - 1
    if i + j > q - 1:
        # rounding put the point just outside the face: back onto the nearest up triangle
        over = i + j - (q - 1)
        if i >= over:
            i -= over
        else:
            j -= over - i
            i = 0
        down = 0
    else:
        down = 1 if (fb - i) + (fc - j) > 1.0 else 0
        if down == 1 and i + j > q - 2:
            down = 0
    # index: up triangles first (row-major over i, j with i + j <= q - 1), then down ones
    # (i + j <= q - 2); see DirectionSet._build for the same order
    if down == 0:
        k = i * q - (i * (i - 1)) // 2 + j
    else:
        k = q * (q + 1) // 2 + i * (q - 1) - (i * (i - 1)) // 2 + j
    return f * q * q + k


@njit(cache=True, parallel=True)
def lookup_kernel(n, centres, frames, q, out):
    for i in prange(n.shape[0]):
        out[i] = lookup_one(n[i, 0], n[i, 1], n[i, 2], centres, frames, q)


@njit(cache=True)
def popcount64(x):
    x = x - ((x >> np.uint64(1)) & np.uint64(0x5555555555555555))
    x = (x & np.uint64(0x3333333333333333)) + ((x >> np.uint64(2)) & np.uint64(0x3333333333333333))
    x = (x + (x >> np.uint64(4))) & np.uint64(0x0F0F0F0F0F0F0F0F)
    return (x * np.uint64(0x0101010101010101)) >> np.uint64(56)


@njit(cache=True, parallel=True)
def popcount_rows(bits, out):
    for r in prange(bits.shape[0]):
        s = 0
        for w in range(bits.shape[1]):
            s += popcount64(bits[r, w])
        out[r] = s


@njit(cache=True, parallel=True)
def bits_to_bool(bits, k, out):
    for r in prange(bits.shape[0]):
        for i in range(k):
            out[r, i] = (bits[r, i >> 6] >> np.uint64(i & 63)) & np.uint64(1)


@njit(cache=True, parallel=True)
def bool_to_bits(mask, out):
    for r in prange(mask.shape[0]):
        for w in range(out.shape[1]):
            out[r, w] = np.uint64(0)
        for i in range(mask.shape[1]):
            if mask[r, i]:
                out[r, i >> 6] |= np.uint64(1) << np.uint64(i & 63)


@njit(cache=True)
def above_words(dirs, nx, ny, nz, floor, words):
    """``words``: the bitset of the directions i with dirs[i] . (nx, ny, nz) > floor; returns
    the margin, min_i |dirs[i] . n - floor| (within it no direction changes side)."""
    k = dirs.shape[0]
    margin = np.inf
    for w in range(words.shape[0]):
        acc = np.uint64(0)
        for i in range(w * 64, min(k, w * 64 + 64)):
            t = dirs[i, 0] * nx + dirs[i, 1] * ny + dirs[i, 2] * nz - floor
            margin = min(margin, abs(t))
            if t > 0.0:
                acc |= np.uint64(1) << np.uint64(i - w * 64)
        words[w] = acc
    return margin


@njit(cache=True, parallel=True)
def above_bits(dirs, normals, floor, out):
    """out[r]: the bitset of the directions i with dirs[i] . normals[r] > floor."""
    for r in prange(normals.shape[0]):
        above_words(dirs, normals[r, 0], normals[r, 1], normals[r, 2], floor, out[r])
