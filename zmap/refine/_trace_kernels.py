"""Numba kernels of the traces that split e-cells (conventions: :mod:`zmap.refine._ez_kernels`).

A cell whose boundary holds two breaks of one kind is split along the trace joining them: a
circle arc whose sagitta comes from the crossings found along the trace in the neighbouring
cells, or the polyline through a wall's corner (:func:`cell_geometry`). No validation here.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ._coons_kernels import _edge_xy, _find
from ._edge_kernels import BREAK_JUMP, BREAK_KINK

__all__ = ["CORNER_TURN", "MAX_WALK", "MIN_LEVER", "cell_geometry"]


# A cell whose two boundary breaks turn by more than this is taken as holding a corner of
# the wall (trace through the corner), else as a smooth arc (trace through its midpoint).
CORNER_TURN = math.radians(30.0)
# A neighbouring crossing closer than this share of the grid interval does not steer the trace.
MIN_LEVER = 0.5
# Cells walked along the trace to find that crossing.
MAX_WALK = 4


@njit(cache=True, error_model="numpy")
def _far_crossing(ecell_ids, out_nb, out_bk, out_pts, corner, ci, cj, k, ri, rj, px, py, lever, nx, ny, dx, dy):
    """Walk the trace from cell (ci, cj) out through its break on edge k to the first
    crossing at least ``lever`` from (px, py).

    Returns (found, qx, qy, i, j, k_out): the crossing in the cell-local coordinates of cell
    (ri, rj), the cell it closes and the edge through which the trace leaves that cell. The
    walk stops (not found) at a cell that is not a plain two-break cell or holds a corner.
    """
    cur_i, cur_j = ci, cj
    for _ in range(MAX_WALK):
        ni, nj = cur_i, cur_j
        if k == 0:
            nj -= 1
        elif k == 1:
            ni += 1
        elif k == 2:
            nj += 1
        else:
            ni -= 1
        if ni < 0 or nj < 0 or ni > nx - 2 or nj > ny - 2:
            break
        nc = _find(ecell_ids, ni * (ny - 1) + nj)
        if nc < 0 or out_nb[nc] != 2 or corner[nc]:
            break
        shared = (k + 2) % 4
        if out_bk[nc, 0] == shared:
            other = 1
        elif out_bk[nc, 1] == shared:
            other = 0
        else:
            break
        qx = out_pts[nc, 2 * other, 0] + (ni - ri) * dx
        qy = out_pts[nc, 2 * other, 1] + (nj - rj) * dy
        k = out_bk[nc, other]
        if math.hypot(qx - px, qy - py) >= lever:
            return True, qx, qy, ni, nj, k
        cur_i, cur_j = ni, nj
    return False, 0.0, 0.0, 0, 0, 0


@njit(cache=True, error_model="numpy")
def _line_gap(ax, ay, bx, by, px, py):
    """Distance of P from the line through A and B."""
    L = math.hypot(bx - ax, by - ay)
    return abs((bx - ax) * (py - ay) - (by - ay) * (px - ax)) / L


@njit(cache=True, error_model="numpy")
def cell_geometry(ecell_ids, slots, brk_kind, brk_t, nx, ny, dx, dy, straight_tol, out_nb, out_bk, out_bt, out_pts,
                  out_arc):
    """Wall/edge trace of every e-cell with exactly two boundary breaks.

    ``out_nb`` (C,) number of breaks on the cell's boundary that a trace may join (its jumps,
    or its kinks where it has no jump); for two: ``out_bk``/``out_bt``
    (C, 2) their local edges and parameters and ``out_pts`` (C, 3, 2) the trace P1, M, P2 in
    cell-local metric coordinates, ``out_arc`` (C, 3) the trace's circle (centre x, y and
    radius; radius 0 for a polyline P1-M-P2). A smooth wall is the arc through P1 and P2
    with the mean sagitta of the circles through them and the crossing beyond each (found
    by walking the trace at least ``MIN_LEVER`` grid intervals out). A wall corner is
    taken where the traces on both sides are straight (the next crossing out lies within
    ``straight_tol`` of their line), turn by more than ``CORNER_TURN`` and meet inside the
    cell: the trace is then the polyline through that meeting point.
    """
    C = ecell_ids.shape[0]
    for c in range(C):
        # the trace joins two breaks: two jumps (a wall) if there are exactly two, else two
        # kinks (a sharp edge) when there are no jumps; any other count is no single trace
        nj = 0
        nk = 0
        for k in range(4):
            sl = slots[c, k]
            if sl >= 0:
                if brk_kind[sl] == BREAK_JUMP:
                    nj += 1
                elif brk_kind[sl] == BREAK_KINK:
                    nk += 1
        want = BREAK_JUMP if nj > 0 else BREAK_KINK
        nb = 0
        for k in range(4):
            sl = slots[c, k]
            if sl >= 0 and brk_kind[sl] == want:
                if nb < 2:
                    out_bk[c, nb] = k
                    out_bt[c, nb] = brk_t[sl]
                    X, Y = _edge_xy(k, brk_t[sl], dx, dy)
                    out_pts[c, 2 * nb, 0] = X
                    out_pts[c, 2 * nb, 1] = Y
                nb += 1
        out_nb[c] = nb
    corner = np.zeros(C, dtype=np.bool_)
    for c in range(C):  # pass 1: corners (straight traces on both sides meeting in the cell)
        if out_nb[c] == 2:
            corner[c] = _trace(c, ecell_ids, out_nb, out_bk, out_pts, out_arc, corner, nx, ny, dx, dy, straight_tol, True)
    for c in range(C):  # pass 2: arcs, from crossings not beyond a corner
        if out_nb[c] == 2 and not corner[c]:
            _trace(c, ecell_ids, out_nb, out_bk, out_pts, out_arc, corner, nx, ny, dx, dy, straight_tol, False)


@njit(cache=True, error_model="numpy")
def _trace(c, ecell_ids, out_nb, out_bk, out_pts, out_arc, corner, nx, ny, dx, dy, straight_tol, corners):
    """Corner pass (``corners=True``: set M at the corner, return whether there is one) or
    arc pass (set M and the circle of a smooth trace)."""
    ci = ecell_ids[c] // (ny - 1)
    cj = ecell_ids[c] - ci * (ny - 1)
    p1x = out_pts[c, 0, 0]
    p1y = out_pts[c, 0, 1]
    p2x = out_pts[c, 2, 0]
    p2y = out_pts[c, 2, 1]
    mx = 0.5 * (p1x + p2x)
    my = 0.5 * (p1y + p2y)
    L = math.hypot(p2x - p1x, p2y - p1y)
    if corners:
        out_pts[c, 1, 0] = mx
        out_pts[c, 1, 1] = my
    if L <= 1e-12 * (dx + dy):
        return False
    wx = (p2x - p1x) / L
    wy = (p2y - p1y) / L
    lever = MIN_LEVER * min(dx, dy)
    qx = np.zeros(2)
    qy = np.zeros(2)
    has = np.zeros(2, dtype=np.bool_)
    straight = np.zeros(2, dtype=np.bool_)
    for b in range(2):
        px_ = p1x if b == 0 else p2x
        py_ = p1y if b == 0 else p2y
        found, qx[b], qy[b], qi, qj, qk = _far_crossing(ecell_ids, out_nb, out_bk, out_pts, corner, ci, cj,
                                                         out_bk[c, b], ci, cj, px_, py_, lever, nx, ny, dx, dy)
        has[b] = found
        if found and corners:
            f2, rx, ry, _, _, _ = _far_crossing(ecell_ids, out_nb, out_bk, out_pts, corner, qi, qj, qk, ci, cj,
                                                qx[b], qy[b], lever, nx, ny, dx, dy)
            straight[b] = f2 and _line_gap(qx[b], qy[b], px_, py_, rx, ry) <= straight_tol
    if corners:
        if not (has[0] and has[1] and straight[0] and straight[1]):
            return False
        d1x = p1x - qx[0]
        d1y = p1y - qy[0]
        d2x = qx[1] - p2x
        d2y = qy[1] - p2y
        cross = d1x * d2y - d1y * d2x
        turn = math.atan2(abs(cross), d1x * d2x + d1y * d2y)
        if turn <= CORNER_TURN or cross == 0.0:
            return False  # no corner, or the two traces run back along one line (trj8)
        a = ((p2x - p1x) * d2y - (p2y - p1y) * d2x) / cross
        cx = p1x + a * d1x
        cy = p1y + a * d1y
        slack = 1e-9 * (dx + dy)
        if not (-slack <= cx <= dx + slack and -slack <= cy <= dy + slack):
            return False
        out_pts[c, 1, 0] = min(max(cx, 0.0), dx)
        out_pts[c, 1, 1] = min(max(cy, 0.0), dy)
        return True
    # smooth wall: the arc through P1 and P2 whose sagitta is the mean of those of the
    # circles through Q, P1 and P2 on either side
    sag = 0.0
    cnt = 0
    for b in range(2):
        if not has[b]:
            continue
        ok, sg = _arc_sagitta(qx[b], qy[b], p1x, p1y, p2x, p2y)
        if ok:
            sag += sg
            cnt += 1
    if cnt == 0:
        return False
    sag = min(max(sag / cnt, -0.5 * L), 0.5 * L)
    if abs(sag) <= 1e-9 * L:
        return False
    out_pts[c, 1, 0] = mx - sag * wy
    out_pts[c, 1, 1] = my + sag * wx
    # circle through P1, M, P2: centre on the chord's bisector, (L/2)^2 = sag*(2*rho - sag)
    rho = (0.25 * L * L + sag * sag) / (2.0 * abs(sag))
    off = rho - abs(sag)  # centre's distance from the chord, on the side away from M
    sgn = 1.0 if sag > 0 else -1.0
    out_arc[c, 0] = mx + sgn * off * wy
    out_arc[c, 1] = my - sgn * off * wx
    out_arc[c, 2] = rho
    return False


@njit(cache=True, error_model="numpy")
def _arc_sagitta(ax, ay, p1x, p1y, p2x, p2y):
    """Signed sagitta (along the left normal of P1->P2) of the minor arc P1-P2 of the circle
    through A, P1, P2; (False, 0) when the three are collinear."""
    d = 2.0 * (ax * (p1y - p2y) + p1x * (p2y - ay) + p2x * (ay - p1y))
    L = math.hypot(p2x - p1x, p2y - p1y)
    scale = max(math.hypot(ax - p1x, ay - p1y), L)
    if abs(d) <= 1e-12 * scale * scale:
        return True, 0.0
    a2 = ax * ax + ay * ay
    b2 = p1x * p1x + p1y * p1y
    c2 = p2x * p2x + p2y * p2y
    ux = (a2 * (p1y - p2y) + b2 * (p2y - ay) + c2 * (ay - p1y)) / d
    uy = (a2 * (p2x - p1x) + b2 * (ax - p2x) + c2 * (p1x - ax)) / d
    rho = math.hypot(p1x - ux, p1y - uy)
    mx = 0.5 * (p1x + p2x)
    my = 0.5 * (p1y + p2y)
    vx = mx - ux
    vy = my - uy
    dist = math.hypot(vx, vy)
    if dist <= 1e-12 * rho:
        return False, 0.0
    ex = ux + rho * vx / dist - mx
    ey = uy + rho * vy / dist - my
    # left normal of P1->P2 is (-wy, wx)
    return True, (-ex * (p2y - p1y) + ey * (p2x - p1x)) / L
