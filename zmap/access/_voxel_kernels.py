"""Numba kernels that build the voxel map of :mod:`zmap.access.voxelmap`: the faces' samples
folded into their boundary voxels and half-voxel pieces, the exterior painted, the faces'
orientation votes and the patches' slabs (no validation, flat arrays only).

Voxel (i, j, l) covers ``origin + d * [i, i + 1) x [j, j + 1) x [l, l + 1)``; its centre is
``origin + d * (i + 0.5, ...)``. States: 0 exterior, 1 boundary, 2 interior, 3 not yet painted.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ._direction_kernels import above_words, lookup_one

__all__ = ["EXTERIOR", "BOUNDARY", "INTERIOR", "UNPAINTED", "accumulate", "paint_exterior", "orientation_votes",
           "piece_accumulate", "patch_slab"]

EXTERIOR, BOUNDARY, INTERIOR, UNPAINTED = 0, 1, 2, 3


@njit(cache=True)
def _hemisphere(dirs, nx, ny, nz, words, last):
    """The bitset of the directions strictly above the plane of normal n (bit i set where
    dirs[i] . n > 0) in ``words``, made again only when n leaves the margin of the normal it
    was made for. ``last`` holds that normal and its margin min_i |dirs[i] . n| (start: NaN,
    NaN, NaN, -1): a normal within the margin, less 1e-12 of rounding, sets the same bits,
    since no dot product can change sign. A planar face's samples, and neighbours on a curved
    one, so cost a fraction of the k dot products each."""
    dx, dy, dz = nx - last[0], ny - last[1], nz - last[2]
    if math.sqrt(dx * dx + dy * dy + dz * dz) + 1e-12 < last[3]:
        return
    margin = above_words(dirs, nx, ny, nz, 0.0, words)
    last[0], last[1], last[2], last[3] = nx, ny, nz, margin


@njit(cache=True)
def accumulate(vox, pts, nrm, kmax, face, weight, centres, frames, q, hv, hl, exact, dirs,
               vl, light, curv, surf, crease, cos_crease, psum, nsum, area, nsamp, first, pmin, pmax):
    """Fold each sample into its boundary voxel: V' &= H_V(t), L' |= H_L(t), curvature, surface.

    ``vox[s]`` is the boundary voxel of sample s; ``exact`` = 1 replaces H_V / H_L of the tessel
    by the exact hemisphere of the sample's normal (bit i set where dirs[i] . n > 0); 2 leaves
    ``vl`` and ``light`` alone (the caller folds them from the half-voxel pieces').
    """
    W = vl.shape[1]
    words = np.zeros(W, dtype=np.uint64)  # the last hemisphere made (:func:`_hemisphere`)
    last = np.array([np.nan, np.nan, np.nan, -1.0])
    for s in range(vox.shape[0]):
        b = vox[s]
        nx, ny, nz = nrm[s, 0], nrm[s, 1], nrm[s, 2]
        if exact == 2:  # the caller folds the bitsets itself
            pass
        elif exact:
            _hemisphere(dirs, nx, ny, nz, words, last)
            for w in range(W):
                vl[b, w] &= words[w]
                light[b, w] |= words[w]
        else:
            t = lookup_one(nx, ny, nz, centres, frames, q)
            for w in range(W):
                if t < 0:  # a sample without a normal: nothing is known visible (conservative)
                    vl[b, w] = np.uint64(0)
                else:
                    vl[b, w] &= hv[t, w]
                    light[b, w] |= hl[t, w]
        if kmax[s] > curv[b]:
            curv[b] = kmax[s]
        if nsamp[b] == 0:
            surf[b] = face[s]
            first[b, 0] = nx
            first[b, 1] = ny
            first[b, 2] = nz
        elif surf[b] != face[s]:
            surf[b] = -1
        if surf[b] == -1 and first[b, 0] * nx + first[b, 1] * ny + first[b, 2] * nz < cos_crease:
            crease[b] = 1
        nsamp[b] += 1
        for c in range(3):
            psum[b, c] += pts[s, c]
            if pts[s, c] < pmin[b, c]:
                pmin[b, c] = pts[s, c]
            if pts[s, c] > pmax[b, c]:
                pmax[b, c] = pts[s, c]
            nsum[b, c] += nrm[s, c]
        area[b] += weight[s]


@njit(cache=True)
def paint_exterior(state):
    """Paint spreading: every non-boundary voxel 6-connected to the grid's border is exterior;
    the rest of the non-boundary voxels are interior. Returns the number of exterior voxels."""
    nx, ny, nz = state.shape
    n = nx * ny * nz
    stack = np.empty(n, dtype=np.int64)
    top = 0
    for i in range(nx):
        for j in range(ny):
            for l in range(nz):
                if i == 0 or j == 0 or l == 0 or i == nx - 1 or j == ny - 1 or l == nz - 1:
                    if state[i, j, l] == UNPAINTED:
                        state[i, j, l] = EXTERIOR
                        stack[top] = (i * ny + j) * nz + l
                        top += 1
    painted = top
    while top > 0:
        top -= 1
        f = stack[top]
        l = f % nz
        j = (f // nz) % ny
        i = f // (ny * nz)
        for m in range(6):
            a, b, c = i, j, l
            if m == 0:
                a -= 1
            elif m == 1:
                a += 1
            elif m == 2:
                b -= 1
            elif m == 3:
                b += 1
            elif m == 4:
                c -= 1
            else:
                c += 1
            if a < 0 or b < 0 or c < 0 or a >= nx or b >= ny or c >= nz:
                continue
            if state[a, b, c] == UNPAINTED:
                state[a, b, c] = EXTERIOR
                stack[top] = (a * ny + b) * nz + c
                top += 1
                painted += 1
    for i in range(nx):
        for j in range(ny):
            for l in range(nz):
                if state[i, j, l] == UNPAINTED:
                    state[i, j, l] = INTERIOR
    return painted


@njit(cache=True)
def orientation_votes(pts, nrm, face, origin, d, state, out):
    """Per face, count samples whose normal points (one voxel away) into an exterior voxel
    (out[f, 0]) and into an interior one (out[f, 1])."""
    nx, ny, nz = state.shape
    for s in range(pts.shape[0]):
        for sign in range(2):
            fac = d if sign == 0 else -d
            x = (pts[s, 0] + fac * nrm[s, 0] - origin[0]) / d
            y = (pts[s, 1] + fac * nrm[s, 1] - origin[1]) / d
            z = (pts[s, 2] + fac * nrm[s, 2] - origin[2]) / d
            i, j, l = int(np.floor(x)), int(np.floor(y)), int(np.floor(z))
            if i < 0 or j < 0 or l < 0 or i >= nx or j >= ny or l >= nz:
                st = EXTERIOR
            else:
                st = state[i, j, l]
            if sign == 0:
                if st == EXTERIOR:
                    out[face[s], 0] += 1
                elif st == INTERIOR:
                    out[face[s], 1] += 1
            else:
                if st == INTERIOR:
                    out[face[s], 2] += 1
                elif st == EXTERIOR:
                    out[face[s], 3] += 1


@njit(cache=True)
def piece_accumulate(piece, pts, nrm, centres, frames, q, hv, hl, exact, dirs, vl, light, psum, nsum, pmin, pmax):
    """Fold samples into pieces (one face's samples in one voxel): V'_l (AND) and L' (OR) of
    each sample's exact hemisphere, or of H_V / H_L of its tessel, as :func:`accumulate` does
    for voxels (``exact`` = 2: neither); point and normal sums, samples' box."""
    W = light.shape[1]
    words = np.zeros(W, dtype=np.uint64)  # the last hemisphere made (:func:`_hemisphere`)
    last = np.array([np.nan, np.nan, np.nan, -1.0])
    for s in range(piece.shape[0]):
        p = piece[s]
        nx, ny, nz = nrm[s, 0], nrm[s, 1], nrm[s, 2]
        if exact == 2:  # the caller folds the bitsets itself
            pass
        elif exact:
            _hemisphere(dirs, nx, ny, nz, words, last)
            for w in range(W):
                vl[p, w] &= words[w]
                light[p, w] |= words[w]
        else:
            t = lookup_one(nx, ny, nz, centres, frames, q)
            for w in range(W):
                if t < 0:  # a sample without a normal: nothing is known visible (conservative)
                    vl[p, w] = np.uint64(0)
                else:
                    vl[p, w] &= hv[t, w]
                    light[p, w] |= hl[t, w]
        for c in range(3):
            psum[p, c] += pts[s, c]
            nsum[p, c] += nrm[s, c]
            pmin[p, c] = min(pmin[p, c], pts[s, c])
            pmax[p, c] = max(pmax[p, c], pts[s, c])


@njit(cache=True)
def patch_slab(vox, pts, nrm, point, normal, step, slab, grow):
    """Bounds of each boundary voxel's surface patch from its samples.

    ``slab[b]``: half-thickness of the patch about the plane through ``point[b]`` with normal
    ``normal[b]``: the samples' largest distance from it, plus 2 d' (``step``) times the
    largest sine s_b between a sample's normal and ``normal[b]`` (the patch runs on up to d'
    past its outer samples, turning at most as much again), so that every patch point x has
    ``(x - point[b]) . normal[b] >= -slab[b]``. ``grow[b, c]``: how far the patch can reach
    along axis c past its samples' box, ``d' min(1, t_c + s_b)``, t_c the largest
    ``sqrt(1 - n_c^2)`` of its samples' normals (a move of d' along the surface changes
    coordinate c by at most d' times that): 1e-6 d' across a flat face square to an axis.
    Where b has no mean normal: slab inf, grow d'.
    """
    mb = point.shape[0]
    dev = np.zeros(mb)
    sn = np.zeros(mb)
    tang = np.zeros((mb, 3))
    for s in range(vox.shape[0]):
        b = vox[s]
        mx, my, mz = normal[b, 0], normal[b, 1], normal[b, 2]
        t = abs((pts[s, 0] - point[b, 0]) * mx + (pts[s, 1] - point[b, 1]) * my + (pts[s, 2] - point[b, 2]) * mz)
        if t > dev[b]:
            dev[b] = t
        ux, uy, uz = nrm[s, 0], nrm[s, 1], nrm[s, 2]
        cx = uy * mz - uz * my
        cy = uz * mx - ux * mz
        cz = ux * my - uy * mx
        c = np.sqrt(cx * cx + cy * cy + cz * cz)
        if c > sn[b]:
            sn[b] = c
        # sqrt(1 - n_c^2) from the other two components: exactly 0 on an axis
        tx = np.sqrt(uy * uy + uz * uz)
        ty = np.sqrt(ux * ux + uz * uz)
        tz = np.sqrt(ux * ux + uy * uy)
        tang[b, 0] = max(tang[b, 0], tx)
        tang[b, 1] = max(tang[b, 1], ty)
        tang[b, 2] = max(tang[b, 2], tz)
    for b in range(mb):
        if normal[b, 0] == 0.0 and normal[b, 1] == 0.0 and normal[b, 2] == 0.0:
            slab[b] = np.inf
            for c in range(3):
                grow[b, c] = step
        else:
            slab[b] = dev[b] + 2.0 * step * sn[b]
            for c in range(3):
                # never flat: the casting's lines must cross a query's box, not graze it
                grow[b, c] = max(step * min(1.0, tang[b, c] + sn[b]), 1e-6 * step)
