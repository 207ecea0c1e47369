"""Numba kernels of the ball-end tests of paper 002 §4.6 (:mod:`zmap.access.tool`): the ball
fits (no material within its radius) and conditions 1-3 as bitsets over the shell of boundary
voxels around it (no validation, flat arrays only).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ._direction_kernels import lookup_one
from ._voxel_kernels import BOUNDARY, EXTERIOR

__all__ = ["ball_conditions", "ball_fits"]


@njit(cache=True)
def _shell_conditions(b, vg, bxyz, centre, origin, d, index, state, r_in, r_out, bad, cap, centres, frames, q, out):
    """Conditions 1-3 of :func:`ball_conditions` for voxel b, ANDed into ``out[b]`` (which holds
    ``V'_g(b)``); False as soon as a boundary or interior voxel centre lies closer than
    ``r_in`` to the ball's centre (the ball would cut material). Only the columns of the
    voxel grid and the stretch of each column that the sphere of radius ``r_out`` meets are
    visited (a cell of slack; each centre is still tested against both radii)."""
    nx, ny, nz = index.shape
    W = vg.shape[1]
    reach = int(np.ceil(r_out / d)) + 1
    cx = (centre[b, 0] - origin[0]) / d - 0.5
    cy = (centre[b, 1] - origin[1]) / d - 0.5
    cz = (centre[b, 2] - origin[2]) / d - 0.5
    ic, jc, lc = int(np.round(cx)), int(np.round(cy)), int(np.round(cz))
    r2 = (r_out / d) ** 2
    px, py, pz = centre[b, 0], centre[b, 1], centre[b, 2]
    for i in range(max(0, ic - reach), min(nx, ic + reach + 1)):
        dx = (i - cx) * d
        for j in range(max(0, jc - reach), min(ny, jc + reach + 1)):
            dy = (j - cy) * d
            rest = r2 - (i - cx) ** 2 - (j - cy) ** 2
            if rest < -1.0:  # the column misses the sphere (by more than rounding)
                continue
            t = np.sqrt(max(rest, 0.0)) + 1.0
            l0 = max(0, lc - reach, int(np.floor(cz - t)))
            l1 = min(nz, lc + reach + 1, int(np.ceil(cz + t)) + 1)
            for l in range(l0, l1):
                st = state[i, j, l]
                if st == EXTERIOR:
                    continue
                dz = (l - cz) * d
                r = np.sqrt(dx * dx + dy * dy + dz * dz)
                if r < r_in:
                    return False
                if st != BOUNDARY or r > r_out:
                    continue
                m = index[i, j, l]
                tt = lookup_one(bxyz[m, 0] - px, bxyz[m, 1] - py, bxyz[m, 2] - pz, centres, frames, q)
                if tt < 0:  # w's centre on the ball's centre: the ball cannot be there (conservative)
                    for w in range(W):
                        out[b, w] = np.uint64(0)
                elif bad[m] & 2:
                    for w in range(W):
                        out[b, w] &= cap[tt, w]
                else:
                    for w in range(W):
                        out[b, w] &= vg[m, w] | cap[tt, w]
    return True


@njit(cache=True, parallel=True)
def ball_conditions(vg, bxyz, centre, origin, d, index, state, r_in, r_out, bad, cap, centres, frames, q, out):
    """Conditions 1-3 of paper 002 §4.6 as bitsets, for all directions at once.

    The boundary voxels w whose centres lie within [r_in, r_out] of the ball's centre
    ``centre[b]`` form the shell the eraser's surface may meet (E(v) before the half-space
    test). w belongs to E_n(v) unless n lies in ``cap[t]`` (t: the tessel of x_w - c_v), the
    directions for which w lies beyond the eraser's equator. So
    ``A(v) = V'_g(v) & AND_w (V'_g(w) | cap[t_w])`` with ``V'_g(w)`` replaced by nothing where
    w is bad as a neighbour (``bad`` bit 2); v itself must not be bad (bit 1), and the ball
    must fit: no boundary or interior voxel centre closer than r_in. One pass over the sphere
    per voxel, in parallel, with no neighbour lists.
    """
    mb = bxyz.shape[0]
    W = vg.shape[1]
    for b in prange(mb):
        for w in range(W):
            out[b, w] = np.uint64(0) if bad[b] & 1 else vg[b, w]
        if bad[b] & 1:
            continue
        if not _shell_conditions(b, vg, bxyz, centre, origin, d, index, state, r_in, r_out, bad, cap, centres,
                                 frames, q, out):
            for w in range(W):
                out[b, w] = np.uint64(0)


@njit(cache=True, parallel=True)
def ball_fits(centre, origin, d, state, r_in, out):
    """``out[b]`` True where no boundary or interior voxel centre lies closer than ``r_in`` to
    ``centre[b]`` (the ball of the capsule test holds no material, to half a voxel diagonal)."""
    nx, ny, nz = state.shape
    reach = int(np.ceil(r_in / d)) + 1
    for b in prange(centre.shape[0]):
        cx = (centre[b, 0] - origin[0]) / d - 0.5
        cy = (centre[b, 1] - origin[1]) / d - 0.5
        cz = (centre[b, 2] - origin[2]) / d - 0.5
        ic, jc, lc = int(np.round(cx)), int(np.round(cy)), int(np.round(cz))
        ok = True
        for i in range(max(0, ic - reach), min(nx, ic + reach + 1)):
            if not ok:
                break
            dx = (i - cx) * d
            for j in range(max(0, jc - reach), min(ny, jc + reach + 1)):
                if not ok:
                    break
                dy = (j - cy) * d
                for l in range(max(0, lc - reach), min(nz, lc + reach + 1)):
                    if state[i, j, l] == EXTERIOR:
                        continue
                    dz = (l - cz) * d
                    if dx * dx + dy * dy + dz * dz < r_in * r_in:
                        ok = False
                        break
        out[b] = ok
