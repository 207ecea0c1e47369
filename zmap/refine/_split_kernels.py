"""Numba kernels of the height in a split e-cell (conventions: :mod:`zmap.refine._ez_kernels`).

The point's side of the trace (:func:`_region_a`) gives the boundary data it is blended from:
the line through it parallel to the trace's chord meets the cell boundary at two points whose
side heights are blended linearly (:func:`_split`). No validation here.
"""

from __future__ import annotations

import math

from numba import njit

from ._coons_kernels import _edge_value, _edge_xy

__all__ = ["_split"]


@njit(cache=True, error_model="numpy")
def _perimeter(k, t):
    if k == 0:
        return t
    if k == 1:
        return 1.0 + t
    if k == 2:
        return 3.0 - t
    return 4.0 - t


@njit(cache=True, error_model="numpy")
def _boundary_point(X, Y, dx, dy):
    """(k, t) of the cell side nearest to the boundary point (X, Y)."""
    db = abs(Y)
    dr = abs(dx - X)
    dt = abs(dy - Y)
    dl = abs(X)
    m = min(min(db, dr), min(dt, dl))
    if m == db:
        return 0, min(max(X / dx, 0.0), 1.0)
    if m == dr:
        return 1, min(max(Y / dy, 0.0), 1.0)
    if m == dt:
        return 2, min(max(X / dx, 0.0), 1.0)
    return 3, min(max(Y / dy, 0.0), 1.0)


@njit(cache=True, error_model="numpy")
def _in_region_a(X, Y, p1x, p1y, mx, my, p2x, p2y, s1, s2, dx, dy):
    """Point (X, Y) inside the polygon P1 -> corners CCW from s1 to s2 -> P2 -> M."""
    span = (s2 - s1) % 4.0
    inside = False
    ax = mx  # start from M (the last vertex)
    ay = my
    for idx in range(7):
        if idx == 0:
            bx = p1x
            by = p1y
        elif idx <= 4:
            kk = math.floor(s1) + idx
            if kk - s1 >= span or kk - s1 <= 0.0:
                continue
            cc = int(kk) % 4
            bx = dx if (cc == 1 or cc == 2) else 0.0
            by = dy if (cc == 2 or cc == 3) else 0.0
        elif idx == 5:
            bx = p2x
            by = p2y
        else:
            bx = mx
            by = my
        if (ay > Y) != (by > Y):
            xint = ax + (Y - ay) * (bx - ax) / (by - ay)
            if X < xint:
                inside = not inside
        ax = bx
        ay = by
    return inside


@njit(cache=True, error_model="numpy")
def _region_a(X, Y, P, arc, s1, s2, dx, dy):
    """Side of the trace holding (X, Y): True for the region whose boundary arc runs CCW
    from P1 (perimeter s1) to P2 (s2)."""
    if arc[2] <= 0.0:
        return _in_region_a(X, Y, P[0, 0], P[0, 1], P[1, 0], P[1, 1], P[2, 0], P[2, 1], s1, s2, dx, dy)
    # circular trace: split by the chord, then move the circular segment between chord
    # and arc (on M's side of the chord, inside the circle) to the other side
    mx = 0.5 * (P[0, 0] + P[2, 0])
    my = 0.5 * (P[0, 1] + P[2, 1])
    a = _in_region_a(X, Y, P[0, 0], P[0, 1], mx, my, P[2, 0], P[2, 1], s1, s2, dx, dy)
    cx = P[2, 0] - P[0, 0]
    cy = P[2, 1] - P[0, 1]
    side_p = cx * (Y - P[0, 1]) - cy * (X - P[0, 0])
    side_m = cx * (P[1, 1] - P[0, 1]) - cy * (P[1, 0] - P[0, 0])
    if side_p * side_m > 0.0 and math.hypot(X - arc[0], Y - arc[1]) <= arc[2]:
        # in the segment: on the side of the arc away from M's side of the chord
        m_in_a = _in_region_a(P[1, 0], P[1, 1], P[0, 0], P[0, 1], mx, my, P[2, 0], P[2, 1], s1, s2, dx, dy)
        return not m_in_a
    return a


@njit(cache=True, error_model="numpy")
def _split(z, i, j, u, v, c, slots, edge_ids, offsets, hq, brk_kind, brk_t, bk, bt, pts, arc, dx, dy):
    """Height on the side of the cell's trace that holds the point, from that side's data.

    The line through the point parallel to the trace's chord meets the cell boundary at A
    and B; their boundary hq (taken from the point's side; a hit beyond the side's arc
    is pulled back to the arc's end at the break) are blended linearly along the line.
    """
    X = u * dx
    Y = v * dy
    k1 = bk[c, 0]
    k2 = bk[c, 1]
    t1 = bt[c, 0]
    t2 = bt[c, 1]
    s1 = _perimeter(k1, t1)
    s2 = _perimeter(k2, t2)
    P = pts[c]
    # the region test counts crossings of edges above and to the right of the point, so a
    # point on the cell's top or right side would lie outside both regions: test it a hair inside
    if _region_a(min(X, dx * (1.0 - 1e-12)), min(Y, dy * (1.0 - 1e-12)), P, arc[c], s1, s2, dx, dy):
        sa, ka, ta, sb, kb, tb_ = s1, k1, t1, s2, k2, t2
    else:
        sa, ka, ta, sb, kb, tb_ = s2, k2, t2, s1, k1, t1
    span = (sb - sa) % 4.0
    wx = P[2, 0] - P[0, 0]
    wy = P[2, 1] - P[0, 1]
    L = math.hypot(wx, wy)
    wx /= L
    wy /= L
    lo = -1e300
    hi = 1e300
    if abs(wx) > 1e-15:
        l1 = -X / wx
        l2 = (dx - X) / wx
        lo = max(lo, min(l1, l2))
        hi = min(hi, max(l1, l2))
    if abs(wy) > 1e-15:
        l1 = -Y / wy
        l2 = (dy - Y) / wy
        lo = max(lo, min(l1, l2))
        hi = min(hi, max(l1, l2))
    va, da = _hit(z, i, j, X, Y, lo, wx, wy, c, sa, ka, ta, sb, kb, tb_, span, slots, edge_ids, offsets, hq,
                  brk_kind, brk_t, dx, dy)
    vb, db = _hit(z, i, j, X, Y, hi, wx, wy, c, sa, ka, ta, sb, kb, tb_, span, slots, edge_ids, offsets, hq,
                  brk_kind, brk_t, dx, dy)
    if da + db <= 0.0:
        return va
    return (va * db + vb * da) / (da + db)


@njit(cache=True, error_model="numpy")
def _hit(z, i, j, X, Y, lam, wx, wy, c, sa, ka, ta, sb, kb, tb_, span, slots, edge_ids, offsets, hq, brk_kind, brk_t, dx, dy):
    """Boundary height and distance of the hit ``P + lam*w``, kept on the arc [sa, sb]."""
    k, t = _boundary_point(X + lam * wx, Y + lam * wy, dx, dy)
    s = _perimeter(k, t)
    if (s - sa) % 4.0 <= span:
        return (_edge_value(z, i, j, k, t, 0, slots[c, k], edge_ids, offsets, hq, brk_kind, brk_t, dx, dy), abs(lam))
    if (sa - s) % 4.0 <= (s - sb) % 4.0:  # pull back to the arc's start; the arc runs CCW from it
        k, t = ka, ta
        sd = 1 if (k == 0 or k == 1) else -1
    else:  # to the arc's end; the arc lies CW from it
        k, t = kb, tb_
        sd = -1 if (k == 0 or k == 1) else 1
    ex, ey = _edge_xy(k, t, dx, dy)
    return (_edge_value(z, i, j, k, t, sd, slots[c, k], edge_ids, offsets, hq, brk_kind, brk_t, dx, dy),
            math.hypot(ex - X, ey - Y))
