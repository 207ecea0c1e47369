"""Numba kernels of :mod:`zmap.access.solid` (no validation; contiguous arrays in, ``out`` filled)."""

from __future__ import annotations

import numpy as np
from numba import njit

EXTERIOR, BOUNDARY, INTERIOR = 0, 1, 2
#: the first voxel off the boundary in front of a sample (along its normal) is interior: the paint never
#: reached the air in front of it (a gap narrower than the voxel), or the normal points inward
FRONT_INTERIOR = 1
#: the first voxel off the boundary behind a sample (against its normal) is exterior: the paint reached
#: both sides of the wall (a wall thinner than the voxel), or the normal points inward
BACK_EXTERIOR = 2


@njit(cache=True)
def _state_at(x, y, z, origin, d, state):
    nx, ny, nz = state.shape
    i = int(np.floor((x - origin[0]) / d))
    j = int(np.floor((y - origin[1]) / d))
    k = int(np.floor((z - origin[2]) / d))
    if i < 0 or j < 0 or k < 0 or i >= nx or j >= ny or k >= nz:
        return EXTERIOR
    return state[i, j, k]


@njit(cache=True)
def _first_off_boundary(x, y, z, nx_, ny_, nz_, sign, origin, d, state, reach):
    """State of the first non-boundary voxel met walking from (x, y, z) along ``sign`` times the
    normal in steps of d / 2, from d / 2 up to ``reach`` (BOUNDARY: none within reach)."""
    t = 0.5 * d
    while t <= reach + 1e-12:
        st = _state_at(x + sign * t * nx_, y + sign * t * ny_, z + sign * t * nz_, origin, d, state)
        if st != BOUNDARY:
            return st
        t += 0.5 * d
    return BOUNDARY


@njit(cache=True)
def sample_sides(pts, nrm, origin, d, reach, state, out):
    """Per sample, the flags ``FRONT_INTERIOR | BACK_EXTERIOR``: the first voxel off the
    boundary in front of it (along its normal) is interior, the first one behind it is
    exterior (walking in steps of d / 2 up to ``reach``; 0: a surface between exterior and
    interior, or only boundary voxels within reach)."""
    for s in range(pts.shape[0]):
        f = 0
        if _first_off_boundary(pts[s, 0], pts[s, 1], pts[s, 2], nrm[s, 0], nrm[s, 1], nrm[s, 2], 1.0, origin, d,
                               state, reach) == INTERIOR:
            f |= FRONT_INTERIOR
        if _first_off_boundary(pts[s, 0], pts[s, 1], pts[s, 2], nrm[s, 0], nrm[s, 1], nrm[s, 2], -1.0, origin, d,
                               state, reach) == EXTERIOR:
            f |= BACK_EXTERIOR
        out[s] = f


@njit(cache=True)
def below_top(state, kfloor, ztop, z0, d):
    """The material below the top surface: the non-boundary voxels of column (i, j) whose
    centres lie at or above layer ``kfloor`` and below ``ztop[i, j]`` (the top surface's
    height at the column's centre, -inf where none) become interior, the others exterior.
    ``z0``: the grid's lowest z. Returns the number of interior voxels."""
    nx, ny, nz = state.shape
    n = 0
    for i in range(nx):
        for j in range(ny):
            top = ztop[i, j]
            for k in range(nz):
                if state[i, j, k] == BOUNDARY:
                    continue
                if k >= kfloor and z0 + (k + 0.5) * d < top:
                    state[i, j, k] = INTERIOR
                    n += 1
                else:
                    state[i, j, k] = EXTERIOR
    return n


@njit(cache=True)
def exposed_faces(state, origin, d, per, out):
    """Points on the faces that interior voxels share with exterior voxels (the sides and the
    floor of the material below an open surface, which have no samples): ``per`` x ``per``
    points per face, at the centres of its sub-squares. ``out`` (m, 3) must hold them all;
    returns how many were written."""
    nx, ny, nz = state.shape
    m = 0
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                if state[i, j, k] != INTERIOR:
                    continue
                for a in range(6):
                    ax = a // 2
                    sg = 1 if a % 2 else -1
                    ii, jj, kk = i, j, k
                    if ax == 0:
                        ii += sg
                    elif ax == 1:
                        jj += sg
                    else:
                        kk += sg
                    outside = ii < 0 or jj < 0 or kk < 0 or ii >= nx or jj >= ny or kk >= nz
                    if not outside and state[ii, jj, kk] != EXTERIOR:
                        continue
                    for p in range(per):
                        for q in range(per):
                            u = (p + 0.5) / per
                            v = (q + 0.5) / per
                            c = np.empty(3)
                            w = 1.0 if sg > 0 else 0.0
                            if ax == 0:
                                c[0], c[1], c[2] = i + w, j + u, k + v
                            elif ax == 1:
                                c[0], c[1], c[2] = i + u, j + w, k + v
                            else:
                                c[0], c[1], c[2] = i + u, j + v, k + w
                            if m < out.shape[0]:
                                for t in range(3):
                                    out[m, t] = origin[t] + d * c[t]
                            m += 1
    return m
