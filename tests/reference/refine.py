"""Slow, obvious references for the EZ-map kernels, for tests on small cases only.

Plain Python per point and per edge, dictionaries instead of CSR lookups, numpy where it
reads like the formula. They follow the algorithm as documented in :mod:`zmap.refine.ez`
and :mod:`zmap.refine._ez_kernels`; only the trace midpoint M of a split cell (a walk
along the neighbouring cells) is taken from the fast tables.
"""

from __future__ import annotations

import math

import numpy as np

from zmap.grid import ZMap

__all__ = ["detect_break", "edge_break", "edge_points", "edge_sequence", "evaluate"]


def _edge(ez, eid: int) -> tuple[int, int, int, int, int]:
    nxe = (ez.nx - 1) * ez.ny
    if eid < nxe:
        i, j = divmod(eid, ez.ny)
        return 0, i, j, i + 1, j
    i, j = divmod(eid - nxe, ez.ny - 1)
    return 1, i, j, i, j + 1


def edge_points(ez) -> tuple[np.ndarray, np.ndarray]:
    """Local xy of the e-points, edge by edge, point by point."""
    xs, ys = [], []
    for k, eid in enumerate(ez.edge_ids.tolist()):
        axis, ia, ja, _, _ = _edge(ez, eid)
        n = int(ez.offsets[k + 1] - ez.offsets[k])
        for q in range(1, n + 1):
            t = q / (n + 1)
            xs.append(ez.x0 + (ia + (t if axis == 0 else 0.0)) * ez.dx)
            ys.append(ez.y0 + (ja + (t if axis == 1 else 0.0)) * ez.dy)
    return np.array(xs), np.array(ys)


def edge_sequence(ez, base: ZMap, eid: int) -> np.ndarray:
    """Boundary sequence of an e-edge: first corner, e-points, last corner (float64).

    A windowed wall edge (``ez.window(k)``) is its full sequence: the stored samples of its
    window at their places, the samples either side read with ``np.interp`` between that
    side's knots (evenly spaced over the side's span, the span's ends included)."""
    k = int(np.flatnonzero(ez.edge_ids == eid)[0])
    _, ia, ja, ib, jb = _edge(ez, eid)
    inner = ez.heights[ez.offsets[k]:ez.offsets[k + 1]].astype(np.float64)
    za, zb = base.z[ia, ja], base.z[ib, jb]
    w = ez.window(k) if hasattr(ez, "window") else None
    if w is None:
        return np.concatenate([[za], inner, [zb]])
    a, c, dl, dr = w
    m = int(ez.full_counts()[k]) + 1
    seq = np.full(m + 1, np.nan)
    seq[0], seq[m] = za, zb
    nl = max(dl - 1, 0)
    kept = list(range(max(a, 1), min(c, m - 1) + 1))
    seq[kept] = inner[nl:nl + len(kept)]
    right = inner[nl + len(kept):]
    if a > 0:
        knots = np.concatenate([[za], inner[:nl], [seq[a]]])
        seq[:a] = np.interp(np.arange(a), np.linspace(0, a, dl + 1), knots)
    if c < m:
        knots = np.concatenate([[seq[c]], right, [zb]])
        seq[c + 1:] = np.interp(np.arange(c + 1, m + 1), np.linspace(c, m, dr + 1), knots)
    return seq


def detect_break(seq: np.ndarray, jump_min: float, kink_min: float, ratio: float) -> tuple[int, float]:
    """(kind, t) of the dominant jump, else kink, of a boundary sequence (see the kernel)."""
    m = len(seq) - 1
    if np.isnan(seq).any() or m < 2:
        return 0, -1.0
    d = np.abs(np.diff(seq))
    q = int(np.argmax(d))
    nb = 0.0
    if q > 0:
        nb = max(nb, d[q - 1])
    if q < m - 1:
        nb = max(nb, d[q + 1])
    if d[q] - nb > jump_min and d[q] > ratio * nb:
        return 1, (q + 0.5) / m
    if m < 4:
        return 0, -1.0
    D = np.abs(seq[2:] - 2.0 * seq[1:-1] + seq[:-2])  # D[q-1] at sample q = 1..m-1
    kq = int(np.argmax(D)) + 1
    dl = D[kq - 2] if kq - 1 >= 1 else 0.0
    dr = D[kq] if kq + 1 <= m - 1 else 0.0
    a, total = (kq - 1, D[kq - 1] + dl) if dl >= dr else (kq, D[kq - 1] + dr)
    others = [D[s - 1] for s in range(1, m) if abs(s - kq) > 1]
    rest = max(others) if others else 0.0
    if not (total > kink_min and total > ratio * rest):
        return 0, -1.0
    a = max(a, 1)
    b = min(a + 1, m - 1)
    sl = seq[a] - seq[a - 1]
    sr = seq[b + 1] - seq[b]
    x = 0.5 * (a + b) if sl == sr else (seq[b] - seq[a] + sl * a - sr * b) / (sl - sr)
    return 2, min(max(x, a), b) / m


def edge_break(ez, base: ZMap, eid: int, jump_min: float, kink_min: float, ratio: float) -> tuple[int, float]:
    """(kind, t) of e-edge ``eid``'s break: a windowed edge whose break is forced
    (``ez.window_break(k)``) has it in its window's interval ``b..b+1`` (a jump mid-way, a
    kink where the lines through the samples either side meet); any other is searched for
    (:func:`detect_break` over :func:`edge_sequence`)."""
    k = int(np.flatnonzero(ez.edge_ids == eid)[0])
    seq = edge_sequence(ez, base, eid)
    kind = ez.window_break(k) if hasattr(ez, "window_break") else 0
    if kind == 0 or np.isnan(seq).any():
        return detect_break(seq, jump_min, kink_min, ratio)
    a, c, _, _ = ez.window(k)
    m = len(seq) - 1
    b = min(max(a + 1 if a > 0 else c - 2, 0), m - 1)  # WINDOW_HALF = 1
    if kind == 1:
        return 1, (b + 0.5) / m
    a = max(b, 1)
    b = min(a + 1, m - 1)
    sl = seq[a] - seq[a - 1]
    sr = seq[b + 1] - seq[b]
    x = 0.5 * (a + b) if sl == sr else (seq[b] - seq[a] + sl * a - sr * b) / (sl - sr)
    return 2, min(max(x, a), b) / m


def _edge_value(seq, kind, tb, t, side):
    """Linear through the sequence; across the break, each side extended from its own end."""
    m = len(seq) - 1
    f = t * m
    if kind:
        x = tb * m
        lo = min(max(math.floor(x + 1e-9), 0), m)
        hi = min(max(math.ceil(x - 1e-9), 0), m)
        low = (f <= x) if side == 0 else side < 0
        if low and f > lo:
            return seq[lo] + ((seq[lo] - seq[lo - 1]) * (f - lo) if lo >= 1 else 0.0)
        if not low and f < hi:
            return seq[hi] + ((seq[hi + 1] - seq[hi]) * (f - hi) if hi + 1 <= m else 0.0)
    return float(np.interp(f, np.arange(m + 1), seq))


def evaluate(ez, base: ZMap, x, y) -> np.ndarray:
    """EZ heights point by point (NaN outside :meth:`EZMap.cell_mask`)."""
    from zmap.refine._coons_kernels import (
        _edge_slope,  # the base's slope rule, plain-side tangent at breaks
    )

    tables = ez._tables(base)
    brk = {int(e): (int(k), float(t)) for e, k, t in zip(ez.edge_ids, tables["brk_kind"], tables["brk_t"])}
    cells = ez.cell_mask()
    nx, ny, nxe = ez.nx, ez.ny, (ez.nx - 1) * ez.ny
    xs, ys = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
    out = np.full(xs.shape, np.nan)
    for idx in np.ndindex(xs.shape):
        lx, ly = base.world_to_local(xs[idx], ys[idx])
        fi, fj = (float(lx) - base.x0) / base.dx, (float(ly) - base.y0) / base.dy
        if not (-1e-9 <= fi <= nx - 1 + 1e-9 and -1e-9 <= fj <= ny - 1 + 1e-9):
            continue
        i, j = min(max((math.floor(fi)), 0), nx - 2), min(max((math.floor(fj)), 0), ny - 2)
        u, v = min(max(fi - i, 0.0), 1.0), min(max(fj - j, 0.0), 1.0)
        if not cells[i, j] or np.isnan(base.z[i:i + 2, j:j + 2]).any():
            continue
        ids = [i * ny + j, nxe + (i + 1) * (ny - 1) + j, i * ny + j + 1, nxe + i * (ny - 1) + j]
        corners = [((i, j), (i + 1, j)), ((i + 1, j), (i + 1, j + 1)), ((i, j + 1), (i + 1, j + 1)), ((i, j), (i, j + 1))]

        def value(k, t, side=0, ids=ids, corners=corners):
            eid = ids[k]
            if eid in brk:
                kind, tb = brk[eid]
                return _edge_value(edge_sequence(ez, base, eid), kind, tb, t, side)
            (ia, ja), (ib, jb) = corners[k]
            di, dj, h = (1, 0, ez.dx) if k in (0, 2) else (0, 1, ez.dy)
            sa = _edge_slope(base.z, ia, ja, di, dj, h, -1, ez.edge_ids, tables["brk_kind"])
            sb = _edge_slope(base.z, ib, jb, di, dj, h, 1, ez.edge_ids, tables["brk_kind"])
            za, zb = base.z[ia, ja], base.z[ib, jb]
            c0, c1, c2, c3 = za, za + sa * h / 3, zb - sb * h / 3, zb
            return (1 - t) ** 3 * c0 + 3 * (1 - t) ** 2 * t * c1 + 3 * (1 - t) * t ** 2 * c2 + t ** 3 * c3

        kinds = [brk[ids[k]][0] if ids[k] in brk else 0 for k in range(4)]
        want = 1 if 1 in kinds else 2  # a trace joins two jumps, else two kinks
        breaks = [(k, brk[ids[k]][1]) for k in range(4) if kinds[k] == want]
        c = int(np.searchsorted(tables["ecell_ids"], i * (ny - 1) + j))
        P = tables["pts"][c]
        if len(breaks) == 2 and not np.array_equal(P[0], P[2]):
            out[idx] = _split(value, breaks, P, tables["arc"][c], u * ez.dx, v * ez.dy, ez.dx, ez.dy)
        else:
            zc = base.z
            bil = ((1 - u) * (1 - v) * zc[i, j] + u * (1 - v) * zc[i + 1, j] + (1 - u) * v * zc[i, j + 1]
                   + u * v * zc[i + 1, j + 1])
            b, r, t, l_ = value(0, u), value(1, v), value(2, u), value(3, v)
            h = (1 - v) * b + v * t + (1 - u) * l_ + u * r - bil
            h += tables["bub"][c] * 16 * u * (1 - u) * v * (1 - v)  # the cell's bubble (0: none)
            if breaks:  # breaks but no single trace: kept within the four curves' values
                h = min(max(h, min(b, r, t, l_)), max(b, r, t, l_))
            out[idx] = h
    return out


def _xy(k, t, dx, dy):
    return [(t * dx, 0.0), (dx, t * dy), (t * dx, dy), (0.0, t * dy)][k]


def _perim(k, t):
    return [t, 1 + t, 3 - t, 4 - t][k]


def _winding(poly, X, Y):
    """Winding number of the closed polygon about (X, Y), by summed angles."""
    total = 0.0
    for (ax, ay), (bx, by) in zip(poly, poly[1:] + poly[:1]):
        total += math.atan2((ax - X) * (by - Y) - (ay - Y) * (bx - X), (ax - X) * (bx - X) + (ay - Y) * (by - Y))
    return round(total / (2 * math.pi))


def _split(value, breaks, P, arc, X, Y, dx, dy):
    """The side of the trace (polyline P1-M-P2, or the circle arc through them when
    ``arc[2] > 0``) holding the point, evaluated along the chord direction."""
    (k1, t1), (k2, t2) = breaks
    s1, s2 = _perim(k1, t1), _perim(k2, t2)
    corner_xy = [(0.0, 0.0), (dx, 0.0), (dx, dy), (0.0, dy)]
    span = (s2 - s1) % 4
    arc_corners = [corner_xy[int(c) % 4] for c in range(math.floor(s1) + 1, math.floor(s1) + 5) if 0 < c - s1 < span]
    if arc[2] > 0:
        # region A: the cell's boundary arc from P1 to P2, closed by the circle arc back to P1
        # (sampled densely: a slow but obvious polygon)
        a1 = math.atan2(P[2][1] - arc[1], P[2][0] - arc[0])
        a0 = math.atan2(P[0][1] - arc[1], P[0][0] - arc[0])
        am = math.atan2(P[1][1] - arc[1], P[1][0] - arc[0])
        sweep = (a0 - a1) % (2 * math.pi)  # CCW from P2 to P1
        if not ((am - a1) % (2 * math.pi) < sweep):
            sweep -= 2 * math.pi  # the arc through M runs CW
        back = [(arc[0] + arc[2] * math.cos(a1 + sweep * q / 400), arc[1] + arc[2] * math.sin(a1 + sweep * q / 400))
                for q in range(1, 400)]
        poly = [tuple(P[0])] + arc_corners + [tuple(P[2])] + back
    else:
        poly = [tuple(P[0])] + arc_corners + [tuple(P[2]), tuple(P[1])]
    if _winding(poly, X, Y) != 0:
        arc = ((k1, t1, s1), (k2, t2, s2))
    else:
        arc = ((k2, t2, s2), (k1, t1, s1))
    (ka, ta, sa), (kb, tb, sb) = arc
    span = (sb - sa) % 4
    w = np.array(P[2]) - np.array(P[0])
    w /= np.linalg.norm(w)
    lams = []
    for lo_hi in (0, 1):  # exits of the line P + lam*w from the rectangle, by brute bisection
        sign = -1.0 if lo_hi == 0 else 1.0
        a, b = 0.0, 4.0 * (dx + dy)
        for _ in range(200):
            mid = 0.5 * (a + b)
            px, py = X + sign * mid * w[0], Y + sign * mid * w[1]
            if -1e-15 <= px <= dx + 1e-15 and -1e-15 <= py <= dy + 1e-15:
                a = mid
            else:
                b = mid
        lams.append(sign * a)
    vals, dists = [], []
    for lam in lams:
        hx, hy = X + lam * w[0], Y + lam * w[1]
        gaps = [abs(hy), abs(dx - hx), abs(dy - hy), abs(hx)]
        k = int(np.argmin(gaps))
        t = min(max(hx / dx if k in (0, 2) else hy / dy, 0.0), 1.0)
        s = _perim(k, t)
        if (s - sa) % 4 <= span:
            vals.append(value(k, t))
            dists.append(abs(lam))
        else:
            if (sa - s) % 4 <= (s - sb) % 4:
                k, t, side = ka, ta, (1 if k in (0, 1) else -1)
            else:
                k, t, side = kb, tb, (-1 if k in (0, 1) else 1)
            ex, ey = _xy(k, t, dx, dy)
            vals.append(value(k, t, side))
            dists.append(math.hypot(ex - X, ey - Y))
    if dists[0] + dists[1] <= 0:
        return vals[0]
    return (vals[0] * dists[1] + vals[1] * dists[0]) / (dists[0] + dists[1])



def thin_intervals(seq: np.ndarray, limit: float) -> int:
    """Slow reference of :func:`zmap.refine._ez_kernels.decimate_counts` for one edge.

    ``seq`` is the edge's boundary sequence (corner, e-points, corner; ``m + 1`` values at
    ``q = 0..m``). Returns the fewest intervals ``d`` of the ladder 2, 3, 4, 5, 6, 8, ...
    (``max(d + 1, 5 d // 4)``) below ``m`` such that the sequence read linearly at
    ``q = k m / d`` and interpolated linearly between those knots is within ``limit`` of
    every value; ``m`` if none or a NaN.
    """
    seq = np.asarray(seq, dtype=np.float64)
    m = seq.size - 1
    if np.isnan(seq).any():
        return m
    q = np.arange(m + 1, dtype=np.float64)
    d = 2
    while d < m:
        kq = np.arange(d + 1) * m / d
        if np.all(np.abs(np.interp(q, kq, np.interp(kq, q, seq)) - seq) <= limit):
            return d
        d = max(d + 1, 5 * d // 4)
    return m
