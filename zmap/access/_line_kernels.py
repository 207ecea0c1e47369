"""Numba helpers of the plane grid of lines along a direction n, shared by the visibility
casting (:mod:`zmap.access._cast_kernels`) and the tool test (:mod:`zmap.access._tool_kernels`):
the plane's basis, per axis the line's slab parameters, the grid cells under a box and, per
row of them, the columns whose line crosses it, and the window of cells over a box.

A line of the grid runs through ``u e + v f`` (e, f the plane basis of :func:`_basis`, u, v
cell centres ``u0 + (a + 0.5) cell``) along n; its parameter along n is its height.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["_basis", "_geometry", "_span", "_row", "_box_row", "_window"]


@njit(cache=True)
def _basis(nx, ny, nz):
    # e1 perpendicular to n, e2 = n x e1
    if abs(nx) < 0.9:
        ax, ay, az = 1.0, 0.0, 0.0
    else:
        ax, ay, az = 0.0, 1.0, 0.0
    # e1 = a - (a.n) n, normalised
    dn = ax * nx + ay * ny + az * nz
    ex, ey, ez = ax - dn * nx, ay - dn * ny, az - dn * nz
    r = np.sqrt(ex * ex + ey * ey + ez * ez)
    ex, ey, ez = ex / r, ey / r, ez / r
    fx = ny * ez - nz * ey
    fy = nz * ex - nx * ez
    fz = nx * ey - ny * ex
    return ex, ey, ez, fx, fy, fz


@njit(cache=True)
def _line_setup(n, e, f):
    """Per axis c of direction n: (zero, 1/n_c, e_c/n_c, f_c/n_c, sign n_c)."""
    z = abs(n) < 1e-12
    if z:
        return True, 0.0, 0.0, 0.0, 1.0
    inv = 1.0 / n
    return False, inv, e * inv, f * inv, 1.0 if n > 0 else -1.0


@njit(cache=True)
def _zin(uc, vc, e, f, r, h):
    # the slab test of an axis the line runs parallel to: it misses when |base - centre| > h
    return not (abs(uc * e + vc * f - r) > h)


@njit(cache=True)
def _zcols(uc, e, f, r, h, u0, cell, jlo, jhi):
    """Columns b in [jlo, jhi] whose line (uc, vc_b) passes the slab test of an axis it runs
    parallel to: a range found in closed form, its ends fixed with the exact test."""
    if abs(f) < 1e-300:
        if _zin(uc, 0.0, e, 0.0, r, h):
            return jlo, jhi
        return 1, 0
    w = uc * e - r
    va = (-h - w) / f
    vb = (h - w) / f
    if va > vb:
        va, vb = vb, va
    lo = max(jlo, int(np.ceil((va - u0) / cell - 0.5)) - 1)
    hi = min(jhi, int(np.floor((vb - u0) / cell - 0.5)) + 1)
    while lo <= hi and not _zin(uc, u0 + (lo + 0.5) * cell, e, f, r, h):
        lo += 1
    while hi >= lo and not _zin(uc, u0 + (hi + 0.5) * cell, e, f, r, h):
        hi -= 1
    return lo, hi


@njit(cache=True)
def _geometry(nx, ny, nz):
    """Per direction: the plane basis e, f and, per axis c, (1/n_c, e_c/n_c, f_c/n_c, sign n_c,
    1 where the line runs parallel to axis c's planes) as one tuple of floats."""
    ex, ey, ez, fx, fy, fz = _basis(nx, ny, nz)
    zx, ix_, pex, pfx, sx = _line_setup(nx, ex, fx)
    zy, iy_, pey, pfy, sy = _line_setup(ny, ey, fy)
    zz, iz_, pez, pfz, sz = _line_setup(nz, ez, fz)
    return (ex, ey, ez, fx, fy, fz, ix_, iy_, iz_, pex, pey, pez, pfx, pfy, pfz, sx, sy, sz,
            1.0 if zx else 0.0, 1.0 if zy else 0.0, 1.0 if zz else 0.0)


@njit(cache=True)
def _span(rx, ry, rz, hx, hy, hz, geo, u0, cell, A0, A1, B0, B1):
    """The grid cells (ia..ib, ja..jb) under a box (centre r relative to the grid's origin,
    half extents h) and its per-axis entry / exit parameters on the line through the
    grid's origin: (r -/+ sign h) / n (-/+inf on an axis the line runs parallel to)."""
    ex, ey, ez, fx, fy, fz = geo[0], geo[1], geo[2], geo[3], geo[4], geo[5]
    ae = hx * abs(ex) + hy * abs(ey) + hz * abs(ez)
    af = hx * abs(fx) + hy * abs(fy) + hz * abs(fz)
    pu = rx * ex + ry * ey + rz * ez
    pv = rx * fx + ry * fy + rz * fz
    ia = max(A0, int(np.floor((pu - ae - u0) / cell)))
    ib = min(A1, int(np.floor((pu + ae - u0) / cell)))
    ja = max(B0, int(np.floor((pv - af - u0) / cell)))
    jb = min(B1, int(np.floor((pv + af - u0) / cell)))
    lxa = -1.0e300 if geo[18] else (rx - geo[15] * hx) * geo[6]
    lxb = 1.0e300 if geo[18] else (rx + geo[15] * hx) * geo[6]
    lya = -1.0e300 if geo[19] else (ry - geo[16] * hy) * geo[7]
    lyb = 1.0e300 if geo[19] else (ry + geo[16] * hy) * geo[7]
    lza = -1.0e300 if geo[20] else (rz - geo[17] * hz) * geo[8]
    lzb = 1.0e300 if geo[20] else (rz + geo[17] * hz) * geo[8]
    return pu, pv, ae, af, ia, ib, ja, jb, lxa, lxb, lya, lyb, lza, lzb


@njit(cache=True)
def _row(uc, rx, ry, rz, hx, hy, hz, ja, jb, lxa, lxb, lya, lyb, lza, lzb, geo, u0, cell):
    """Row uc of a box's cells: its column range (cut to the slab of an axis the line runs
    parallel to) and the per-axis entry / exit parameters at column centre 0."""
    jl, jh = ja, jb
    if geo[18]:
        jl, jh = _zcols(uc, geo[0], geo[3], rx, hx, u0, cell, jl, jh)
    if geo[19]:
        jl, jh = _zcols(uc, geo[1], geo[4], ry, hy, u0, cell, jl, jh)
    if geo[20]:
        jl, jh = _zcols(uc, geo[2], geo[5], rz, hz, u0, cell, jl, jh)
    return (jl, jh, lxa - uc * geo[9], lxb - uc * geo[9], lya - uc * geo[10], lyb - uc * geo[10],
            lza - uc * geo[11], lzb - uc * geo[11])


@njit(cache=True)
def _row_tight(uc, rx, ry, rz, hx, hy, hz, ja, jb, lxa, lxb, lya, lyb, lza, lzb, geo, u0, cell):
    """:func:`_row` for a long box (merged skin cubes): its columns cut to the row's chord
    through the box's projection (a hexagon), the columns whose line enters every slab
    before it leaves any. The cut comes from the six pairs of an entry and another axis'
    exit (linear in the column's centre) and is widened by a column; the callers' per-cell
    test decides. (On small boxes it costs more than the cells it saves.)"""
    jl, jh, xa, xb, ya, yb, za, zb = _row(uc, rx, ry, rz, hx, hy, hz, ja, jb, lxa, lxb, lya, lyb, lza, lzb, geo,
                                          u0, cell)
    px, py, pz = geo[12], geo[13], geo[14]
    vlo, vhi = -1.0e300, 1.0e300
    vlo, vhi = _pair_cut(xa, px, yb, py, vlo, vhi)
    vlo, vhi = _pair_cut(xa, px, zb, pz, vlo, vhi)
    vlo, vhi = _pair_cut(ya, py, xb, px, vlo, vhi)
    vlo, vhi = _pair_cut(ya, py, zb, pz, vlo, vhi)
    vlo, vhi = _pair_cut(za, pz, xb, px, vlo, vhi)
    vlo, vhi = _pair_cut(za, pz, yb, py, vlo, vhi)
    if vlo >= vhi:
        return jl, jl - 1, xa, xb, ya, yb, za, zb
    if vlo > -1.0e299:
        jl = max(jl, int(np.floor((vlo - u0) / cell - 0.5)))
    if vhi < 1.0e299:
        jh = min(jh, int(np.ceil((vhi - u0) / cell - 0.5)))
    return jl, jh, xa, xb, ya, yb, za, zb


@njit(cache=True)
def _box_row(wide, uc, rx, ry, rz, hx, hy, hz, ja, jb, lxa, lxb, lya, lyb, lza, lzb, geo, u0, cell):
    """Row uc of a box's cells: :func:`_row_tight` for a wide box (more than 8 columns, where
    the cut pays), else :func:`_row`."""
    if wide:
        return _row_tight(uc, rx, ry, rz, hx, hy, hz, ja, jb, lxa, lxb, lya, lyb, lza, lzb, geo, u0, cell)
    return _row(uc, rx, ry, rz, hx, hy, hz, ja, jb, lxa, lxb, lya, lyb, lza, lzb, geo, u0, cell)


@njit(cache=True)
def _pair_cut(a, pa, b, pb, vlo, vhi):
    """(vlo, vhi) cut to the v where entry ``a - v pa`` comes before exit ``b - v pb``."""
    dd = pb - pa
    cc = b - a
    if dd > 0.0:
        vhi = min(vhi, cc / dd)
    elif dd < 0.0:
        vlo = max(vlo, cc / dd)
    elif not (cc > 0.0):
        vhi = -1.0e300
    return vlo, vhi


@njit(cache=True)
def _window(cmin, cmax, ex, ey, ez, fx, fy, fz, grow, u0, cell, nc):
    cx, cy, cz = 0.5 * (cmin[0] + cmax[0]), 0.5 * (cmin[1] + cmax[1]), 0.5 * (cmin[2] + cmax[2])
    hx, hy, hz = 0.5 * (cmax[0] - cmin[0]), 0.5 * (cmax[1] - cmin[1]), 0.5 * (cmax[2] - cmin[2])
    cu = cx * ex + cy * ey + cz * ez
    cv = cx * fx + cy * fy + cz * fz
    au = hx * abs(ex) + hy * abs(ey) + hz * abs(ez) + grow
    av = hx * abs(fx) + hy * abs(fy) + hz * abs(fz) + grow
    A0 = max(0, int(np.floor((cu - au - u0) / cell)) - 1)
    A1 = min(nc - 1, int(np.floor((cu + au - u0) / cell)) + 1)
    B0 = max(0, int(np.floor((cv - av - u0) / cell)) - 1)
    B1 = min(nc - 1, int(np.floor((cv + av - u0) / cell)) + 1)
    return A0, A1, B0, B1
