"""Numba kernels of the exact swept volume of a cutter along one path piece, ray by ray.

A cutter of revolution (flat, ball or bull nose; vertical axis) whose tip moves along a
piece of the programmed path removes, along the vertical ray at ``(qx, qy)``, the material
between the lowest point of its lower surface over the piece and the highest point of its
top. Both are computed here exactly (to rounding) for the three move kinds of a 3-axis
program: straight lines in 3D, and arcs or helices in the G17, G18 and G19 planes.

Notation: ``h(r)`` is the cutter's lower envelope at radial distance ``r``
(:func:`zmap.sim._tool_kernels._envelope`), ``R`` its radius, ``rc`` its corner radius,
``r0 = R - rc`` the radius of its flat bottom; ``L`` its length above the tip.

Lines
-----
Let the tip go from ``s`` to ``e``, ``Lxy`` the length of its xy projection, ``m`` the slope
``dz / Lxy``, ``s_q`` the position of the ray's foot along the projection and ``e_q`` its
distance from it. With ``sigma`` the signed xy distance of the tip past the foot, the bottom
of the tool on the ray is ``z(s_q) + g(sigma)`` with ``g(sigma) = m sigma + h(sqrt(sigma^2 +
e_q^2))`` on ``|sigma| <= W = sqrt(R^2 - e_q^2)``. ``h`` is convex and non-decreasing on
``[0, R]`` for all three cutters and the distance is convex in ``sigma``, so ``g`` is
convex: its minimum over the piece's ``sigma`` interval is found

* flat: at the end of the interval where the tip is lowest (closed form);
* ball: at ``sigma = -m W / sqrt(1 + m^2)`` clamped to the interval (closed form: there
  ``g' = m + sigma / sqrt(W^2 - sigma^2) = 0``);
* bull: at the root of the non-decreasing ``g'`` bracketed by the interval, by a
  safeguarded false-position search (:func:`_root_increasing`), which keeps a bracket and
  halves it whenever false position shrinks it by less than half: it ends with a bracket
  below ``1e-12`` mm, so the height is exact to rounding.

The tip's vertical moves (``Lxy = 0``) have the bottom at the lowest tip height plus ``h``.

Arcs and helices
----------------
The tip follows ``theta(t) = theta_a + sweep t``, ``rho(t) = r_a + (r_b - r_a) t`` and a
normal coordinate linear in ``t`` (a helix), ``t`` in the piece's ``[t0, t1]``. The piece is
cut into cells at every ``theta`` that is a multiple of 90 degrees (each in-plane coordinate
is monotone inside a cell), at the angles where the ray is nearest to or farthest from the
circle (G17: the ray's own polar angle and its opposite; G18/G19: where the arc's
horizontal coordinate passes the ray's), and at most every 22.5 degrees. In each cell the
distance from the ray is monotone (on a G18/G19 helix, whose normal coordinate also moves,
it has one minimum, found by golden section), so the part of the cell where the tool
reaches the ray (``d <= R``) is one interval whose ends are found by bisection, and the bottom ``f(t) = z(t) +
h(d(t))`` is taken as the least of its values at the interval's ends and at the root of
``f'`` when ``f'`` changes sign from - to + over it. For G17 with a constant radius ``f`` is
convex on every cell within 90 degrees of the ray's polar angle (``h(sqrt(u))`` is convex in
``u = d^2`` for all three cutters and ``u`` is convex in ``theta`` there), which is where
the cutter is narrower than the arc; beyond that (a cutter wider than the arc's radius)
and for G18/G19, the 22.5-degree cells bound the search. Every height returned is the value
of ``f`` at a real point of the piece, so the stock is never cut deeper than the exact
sweep; tests check it against dense sampling at 1 um.

Private: :mod:`zmap.sim.dexel`, :mod:`zmap.sim.heightfield`, :mod:`zmap.sim.tiled` and
:mod:`zmap.sim.history` call these with validated arrays.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ._tool_kernels import _envelope

__all__: list[str] = []

#: parts a G18/G19 arc cell is searched in for the bottom's minima (:func:`_arc_min_cell`)
SUBCELLS = 8
#: piece kinds of the kernels: no cut, a stamp at the tip (raw positions), a straight line;
#: arcs use their plane's number 17, 18 or 19
NO_CUT = 0
STAMP = 1
LINE = 2

#: most disjoint intervals one piece removes from one ray (a helix whose turns are farther
#: apart than the tool is long leaves one per turn)
MAX_INTERVALS = 64
#: scratch floats of the arc search: cell ends of a piece on one ray (16 per turn and more)
SCRATCH = 8192

_HALF_PI = 0.5 * math.pi
_MAX_CELL = math.pi / 8.0


@njit(cache=True, inline="always")
def _h(code, R, rc, r):
    """Lower envelope with ``r`` clamped to ``[0, R]`` (rounding past the rim)."""
    if r > R:
        r = R
    return _envelope(code, R, rc, r)


@njit(cache=True, inline="always")
def _dh(code, R, rc, r):
    """Derivative of the lower envelope; +inf at a ball's or bull's rim."""
    if code == 0:
        return 0.0
    d = r - (R - rc)
    if d <= 0.0:
        return 0.0
    q = rc * rc - d * d
    if q <= 0.0:
        return np.inf
    return d / math.sqrt(q)


@njit(cache=True)
def _line_gprime(code, R, rc, m, e, sig):
    r = math.sqrt(sig * sig + e * e)
    if r == 0.0:
        return m
    return m + _dh(code, R, rc, r) * sig / r


@njit(cache=True)
def _root_increasing(code, R, rc, m, e, a, b, fa, fb):
    """Root of the non-decreasing ``g'`` of a line on ``[a, b]`` with ``fa < 0 < fb``.

    False position kept off the ends, and a bisection after any step that gained less than
    half the bracket: the bracket at least halves every two steps, down to 1e-12 mm.
    """
    bisect = False
    for _ in range(400):
        w = b - a
        if w <= 1e-12:
            break
        c = 0.5 * (a + b)
        if not bisect and math.isfinite(fa) and math.isfinite(fb):
            c = a - fa * w / (fb - fa)
            if not (a + 0.05 * w < c < b - 0.05 * w):
                c = 0.5 * (a + b)
        fc = _line_gprime(code, R, rc, m, e, c)
        if fc < 0.0:
            a, fa = c, fc
        elif fc > 0.0:
            b, fb = c, fc
        else:
            return c
        bisect = b - a > 0.5 * w
    return 0.5 * (a + b)


@njit(cache=True, inline="always")
def line_setup(sx, sy, sz, ex, ey, ez):
    """Per-piece constants of a line: xy length, unit xy direction, slope dz/dxy and the
    ball's ``-m / sqrt(1 + m^2)``."""
    dx = ex - sx
    dy = ey - sy
    lxy = math.sqrt(dx * dx + dy * dy)
    if lxy <= 1e-12:
        return 0.0, 0.0, 0.0, 0.0, 0.0
    m = (ez - sz) / lxy
    return lxy, dx / lxy, dy / lxy, m, -m / math.sqrt(1.0 + m * m)


@njit(cache=True, inline="always")
def line_tip_z(az, ez, m, lxy, tau):
    """The tip's height ``tau`` mm (in xy) along a line from ``az`` to ``ez``, measured from
    whichever end is nearer, so that both ends come out exact."""
    if tau <= 0.5 * lxy:
        return az + m * tau
    return ez - m * (lxy - tau)


@njit(cache=True, inline="always")
def line_reach(code, R, rc, lxy, ux, uy, m, kb, ax, ay, taulo, tauhi, qx, qy):
    """Where a line's tool reaches ray (qx, qy) and where its bottom is lowest.

    The line starts at ``(ax, ay)`` (xy length ``lxy > 0``, direction ``(ux, uy)``, slope
    ``m``, ``kb`` from :func:`line_setup`); positions on it are ``tau``, the xy distance
    from its start. Returns ``(reached, s, e2, lo, hi, tstar)``: the ray's foot ``s`` and
    its squared distance ``e2`` from the line, the part ``[lo, hi]`` of ``[taulo, tauhi]``
    where the tool reaches the ray, and ``tstar``, where the bottom is lowest over the
    whole move's reach. The bottom is convex in ``tau`` (module docstring), so over any
    part of the reach it is lowest at ``tstar`` clamped to that part; finding ``tstar`` on
    the whole move makes every piece of it see the same number.
    """
    vx = qx - ax
    vy = qy - ay
    s = vx * ux + vy * uy
    e = vx * uy - vy * ux
    e2 = e * e
    R2 = R * R
    if e2 > R2:
        return False, 0.0, 0.0, 0.0, 0.0, 0.0
    w = math.sqrt(R2 - e2)
    flo = max(0.0, s - w)
    fhi = min(lxy, s + w)
    lo = max(taulo, s - w)
    hi = min(tauhi, s + w)
    if lo > hi or flo > fhi:
        return False, 0.0, 0.0, 0.0, 0.0, 0.0
    if m == 0.0:
        tstar = s  # a level move: lowest where the ray is nearest
    elif code == 0:
        tstar = flo if m > 0.0 else fhi  # flat: at the end where the tip is lowest
    elif code == 1:
        tstar = s + kb * w
    else:
        e = abs(e)
        glo = _line_gprime(code, R, rc, m, e, flo - s)
        ghi = _line_gprime(code, R, rc, m, e, fhi - s)
        if glo >= 0.0:
            tstar = flo
        elif ghi <= 0.0:
            tstar = fhi
        else:
            tstar = s + _root_increasing(code, R, rc, m, e, flo - s, fhi - s, glo, ghi)
    return True, s, e2, lo, hi, tstar


@njit(cache=True, inline="always")
def line_piece(code, R, rc, L, az, ez, lxy, m, s, e2, tstar, plo, phi):
    """``(bottom, top)`` removed from the ray by the part ``[plo, phi]`` (``plo <= phi``) of a
    line's reach; ``s, e2, tstar`` from :func:`line_reach`."""
    tk = min(max(tstar, plo), phi)
    d = tk - s
    r2 = d * d + e2
    if code == 0:
        h = 0.0
    elif code == 1:  # a ball: R - sqrt(R^2 - r^2)
        h = R - math.sqrt(max(R * R - r2, 0.0))
    else:
        h = _h(code, R, rc, math.sqrt(r2))
    top = max(line_tip_z(az, ez, m, lxy, plo), line_tip_z(az, ez, m, lxy, phi)) + L
    return line_tip_z(az, ez, m, lxy, tk) + h, top


@njit(cache=True)
def line_ray(code, R, rc, L, g, t0, t1, qx, qy, out):
    """Interval the cutter removes from ray ``(qx, qy)`` over parameters ``[t0, t1]`` of the
    line ``g`` (start xyz, end xyz). Writes ``out[0] = bottom, out[1] = top`` and returns
    1, or returns 0 when the cutter never reaches the ray."""
    ax, ay, az, ez = g[0], g[1], g[2], g[5]
    lxy, ux, uy, m, kb = line_setup(ax, ay, az, g[3], g[4], ez)
    if lxy == 0.0:  # a plunge
        d2 = (qx - ax) ** 2 + (qy - ay) ** 2
        if d2 > R * R:
            return 0
        za = az + (ez - az) * t0
        zb = ez if t1 == 1.0 else az + (ez - az) * t1
        out[0] = min(za, zb) + _h(code, R, rc, math.sqrt(d2))
        out[1] = max(za, zb) + L
        return 1
    ok, s, e2, lo, hi, tstar = line_reach(code, R, rc, lxy, ux, uy, m, kb, ax, ay, t0 * lxy, t1 * lxy, qx, qy)
    if not ok:
        return 0
    out[0], out[1] = line_piece(code, R, rc, L, az, ez, lxy, m, s, e2, tstar, lo, hi)
    return 1


# ---- arcs ------------------------------------------------------------------------------------

@njit(cache=True, inline="always")
def _arc_point(plane, ca, cb, th0, sw, ra, dr, na, dn, t):
    """Tip (x, y, z) and its t-derivative on an arc piece at parameter t."""
    th = th0 + sw * t
    rho = ra + dr * t
    c = math.cos(th)
    s = math.sin(th)
    A = ca + rho * c
    B = cb + rho * s
    dA = dr * c - rho * s * sw
    dB = dr * s + rho * c * sw
    n = na + dn * t
    if plane == 17:
        return A, B, n, dA, dB, dn
    if plane == 18:  # (Z, X, Y)
        return B, n, A, dB, dn, dA
    return n, A, B, dn, dA, dB  # 19: (Y, Z, X)


@njit(cache=True)
def _arc_f(code, R, rc, plane, ca, cb, th0, sw, ra, dr, na, dn, t, qx, qy):
    """(f, f', d, z) of the bottom on the ray at parameter t; f = inf where d > R."""
    x, y, z, dx, dy, dz = _arc_point(plane, ca, cb, th0, sw, ra, dr, na, dn, t)
    ox = x - qx
    oy = y - qy
    d = math.sqrt(ox * ox + oy * oy)
    if d > R:
        return np.inf, 0.0, d, z
    f = z + _h(code, R, rc, d)
    if d == 0.0:
        return f, dz, d, z
    return f, dz + _dh(code, R, rc, d) * (ox * dx + oy * dy) / d, d, z


@njit(cache=True)
def _add_split(ts, n, t, t0, t1):
    if t0 < t < t1 and n < ts.shape[0]:
        ts[n] = t
        n += 1
    return n


@njit(cache=True)
def _angle_splits(ts, n, phi, th0, sw, t0, t1):
    """Add every t in (t0, t1) where theta(t) = phi (mod 2 pi)."""
    if sw == 0.0:
        return n
    a = th0 + sw * t0
    b = th0 + sw * t1
    lo = min(a, b)
    hi = max(a, b)
    k = math.ceil((lo - phi) / (2.0 * math.pi))
    ang = phi + k * 2.0 * math.pi
    while ang < hi and n < ts.shape[0]:
        n = _add_split(ts, n, (ang - th0) / sw, t0, t1)
        ang += 2.0 * math.pi
    return n


@njit(cache=True)
def _arc_cells(plane, ca, cb, th0, sw, ra, dr, qx, qy, t0, t1, ts):
    """Sorted cell boundaries of an arc piece for ray (qx, qy); returns their count."""
    n = 0
    ts[n] = t0
    n += 1
    ts[n] = t1
    n += 1
    for k in range(4):
        n = _angle_splits(ts, n, k * _HALF_PI, th0, sw, t0, t1)
    rho = ra + dr * 0.5 * (t0 + t1)
    if plane == 17:
        phq = math.atan2(qy - cb, qx - ca)
        n = _angle_splits(ts, n, phq, th0, sw, t0, t1)
        n = _angle_splits(ts, n, phq + math.pi, th0, sw, t0, t1)
    elif rho > 0.0:
        # the in-plane horizontal coordinate passes the ray's: G18 x = cb + rho sin,
        # G19 y = ca + rho cos
        if plane == 18:
            v = (qx - cb) / rho
            if -1.0 < v < 1.0:
                p = math.asin(v)
                n = _angle_splits(ts, n, p, th0, sw, t0, t1)
                n = _angle_splits(ts, n, math.pi - p, th0, sw, t0, t1)
        else:
            v = (qy - ca) / rho
            if -1.0 < v < 1.0:
                p = math.acos(v)
                n = _angle_splits(ts, n, p, th0, sw, t0, t1)
                n = _angle_splits(ts, n, -p, th0, sw, t0, t1)
    # insertion sort (few entries), then no cell wider than _MAX_CELL of angle
    for i in range(1, n):
        v = ts[i]
        k = i - 1
        while k >= 0 and ts[k] > v:
            ts[k + 1] = ts[k]
            k -= 1
        ts[k + 1] = v
    cap = ts.shape[0] // 2
    m = n
    for i in range(n - 1):
        a = ts[i]
        b = ts[i + 1]
        k = int(math.ceil(abs(sw) * (b - a) / _MAX_CELL))
        for j in range(1, k):
            if m < cap:
                ts[m] = a + (b - a) * j / k
                m += 1
    if m > n:  # the extra points after the sorted ones: sort again
        for i in range(1, m):
            v = ts[i]
            k = i - 1
            while k >= 0 and ts[k] > v:
                ts[k + 1] = ts[k]
                k -= 1
            ts[k + 1] = v
    return m


@njit(cache=True)
def _arc_reach_end(code, R, rc, plane, ca, cb, th0, sw, ra, dr, na, dn, qx, qy, tin, tout):
    """Last t from ``tin`` (ray reached) towards ``tout`` (not reached) where d <= R."""
    for _ in range(100):
        if abs(tout - tin) <= 1e-15:
            break
        tm = 0.5 * (tin + tout)
        if tm == tin or tm == tout:
            break
        d = _arc_f(code, R, rc, plane, ca, cb, th0, sw, ra, dr, na, dn, tm, qx, qy)[2]
        if d <= R:
            tin = tm
        else:
            tout = tm
    return tin


@njit(cache=True)
def _arc_nearest(plane, ca, cb, th0, sw, ra, dr, na, dn, qx, qy, a, b):
    """``(t, d)``: the point of the cell [a, b] nearest to the ray, by golden section (in a
    cell of at most 22.5 degrees the in-plane coordinate is monotone and the normal one
    linear, so the distance has one minimum)."""
    g = 0.3819660112501051
    lo, hi = a, b
    x1 = lo + g * (hi - lo)
    x2 = hi - g * (hi - lo)
    d1 = _arc_d2(plane, ca, cb, th0, sw, ra, dr, na, dn, qx, qy, x1)
    d2 = _arc_d2(plane, ca, cb, th0, sw, ra, dr, na, dn, qx, qy, x2)
    for _ in range(80):
        if hi - lo <= 1e-13:
            break
        if d1 < d2:
            hi = x2
            x2, d2 = x1, d1
            x1 = lo + g * (hi - lo)
            d1 = _arc_d2(plane, ca, cb, th0, sw, ra, dr, na, dn, qx, qy, x1)
        else:
            lo = x1
            x1, d1 = x2, d2
            x2 = hi - g * (hi - lo)
            d2 = _arc_d2(plane, ca, cb, th0, sw, ra, dr, na, dn, qx, qy, x2)
    t = 0.5 * (lo + hi)
    return t, math.sqrt(_arc_d2(plane, ca, cb, th0, sw, ra, dr, na, dn, qx, qy, t))


@njit(cache=True, inline="always")
def _arc_d2(plane, ca, cb, th0, sw, ra, dr, na, dn, qx, qy, t):
    x, y, _, _, _, _ = _arc_point(plane, ca, cb, th0, sw, ra, dr, na, dn, t)
    return (x - qx) ** 2 + (y - qy) ** 2


@njit(cache=True)
def _arc_min_cell(code, R, rc, plane, ca, cb, th0, sw, ra, dr, na, dn, qx, qy, u, v, fu, gu, fv, gv):
    """Least bottom on the reached cell [u, v] (f, f' known at both ends).

    On a G18/G19 arc the bottom need not be convex on a cell: it can fall to a minimum and
    rise to a maximum between two ends where it falls (a bull cutter's torus rolling over a
    vertical arc: 0.0019 mm missed). There the cell is searched in SUBCELLS parts, each
    minimum bracketed by a sign change of f' from - to +.
    """
    if plane != 17:
        best = min(fu, fv)
        a, fa_, ga_ = u, fu, gu
        for k in range(1, SUBCELLS + 1):
            if k == SUBCELLS:
                b, fb_, gb_ = v, fv, gv
            else:
                b = u + (v - u) * k / SUBCELLS
                fb_, gb_, _, _ = _arc_f(code, R, rc, plane, ca, cb, th0, sw, ra, dr, na, dn, b, qx, qy)
            best = min(best, _arc_min_bracket(code, R, rc, plane, ca, cb, th0, sw, ra, dr, na, dn, qx, qy,
                                              a, b, fa_, ga_, fb_, gb_))
            a, fa_, ga_ = b, fb_, gb_
        return best
    return _arc_min_bracket(code, R, rc, plane, ca, cb, th0, sw, ra, dr, na, dn, qx, qy, u, v, fu, gu, fv, gv)


@njit(cache=True)
def _arc_min_bracket(code, R, rc, plane, ca, cb, th0, sw, ra, dr, na, dn, qx, qy, u, v, fu, gu, fv, gv):
    """Least of f at u, v and at the root of f' between them when f' goes from - to +."""
    best = min(fu, fv)
    if not (gu < 0.0 and gv > 0.0):
        return best
    a, b, ga, gb = u, v, gu, gv
    bisect = False
    for _ in range(400):
        w = b - a
        if w <= 1e-15:
            break
        # false position, kept off the ends; a bisection after any step that gained less
        # than half the bracket, so the bracket at least halves every two steps
        c = 0.5 * (a + b)
        if not bisect and math.isfinite(ga) and math.isfinite(gb):
            c = a - ga * w / (gb - ga)
            if not (a + 0.05 * w < c < b - 0.05 * w):
                c = 0.5 * (a + b)
        fc, gc, _, _ = _arc_f(code, R, rc, plane, ca, cb, th0, sw, ra, dr, na, dn, c, qx, qy)
        if fc < best:
            best = fc
        if gc < 0.0:
            a, ga = c, gc
        elif gc > 0.0:
            b, gb = c, gc
        else:
            break
        bisect = b - a > 0.5 * w
    return best


@njit(cache=True)
def arc_ray(code, R, rc, L, plane, ca, cb, th0, sw, ra, rb, na, nb, t0, t1, qx, qy, out, ts):
    """Intervals the cutter removes from ray ``(qx, qy)`` along an arc piece.

    The arc (plane 17, 18 or 19; in-plane centre ``(ca, cb)``, start angle ``th0``, signed
    ``sweep``, radius from ``ra`` to ``rb`` and normal coordinate from ``na`` to ``nb``
    linear in the angle) is cut from parameter ``t0`` to ``t1``. Writes disjoint sorted
    ``[bottom, top]`` rows into ``out`` (shape (MAX_INTERVALS, 2)) and returns their count;
    ``ts`` is scratch of SCRATCH floats.
    """
    dr = rb - ra
    dn = nb - na
    nc = _arc_cells(plane, ca, cb, th0, sw, ra, dr, qx, qy, t0, t1, ts)
    cnt = 0
    # open run of reached cells: its bottom and top so far
    run_lo = np.inf
    run_hi = -np.inf
    fa, ga, da, za = _arc_f(code, R, rc, plane, ca, cb, th0, sw, ra, dr, na, dn, ts[0], qx, qy)
    for i in range(1, nc):
        a = ts[i - 1]
        b = ts[i]
        fb, gb, db, zb = _arc_f(code, R, rc, plane, ca, cb, th0, sw, ra, dr, na, dn, b, qx, qy)
        ina = da <= R
        inb = db <= R
        tm = -1.0
        if not ina and not inb and dn != 0.0 and plane != 17:
            # a G18/G19 helix: the distance need not be monotone in the cell; its least
            # point may reach the ray between two ends that do not
            tm, dm = _arc_nearest(plane, ca, cb, th0, sw, ra, dr, na, dn, qx, qy, a, b)
            if dm > R:
                tm = -1.0
        if ina or inb or tm >= 0.0:
            u, fu, gu, zu = a, fa, ga, za
            v, fv, gv, zv = b, fb, gb, zb
            if tm >= 0.0:
                u = _arc_reach_end(code, R, rc, plane, ca, cb, th0, sw, ra, dr, na, dn, qx, qy, tm, a)
                v = _arc_reach_end(code, R, rc, plane, ca, cb, th0, sw, ra, dr, na, dn, qx, qy, tm, b)
                fu, gu, _, zu = _arc_f(code, R, rc, plane, ca, cb, th0, sw, ra, dr, na, dn, u, qx, qy)
                fv, gv, _, zv = _arc_f(code, R, rc, plane, ca, cb, th0, sw, ra, dr, na, dn, v, qx, qy)
                fm, gm, _, zm = _arc_f(code, R, rc, plane, ca, cb, th0, sw, ra, dr, na, dn, tm, qx, qy)
                lo = min(_arc_min_cell(code, R, rc, plane, ca, cb, th0, sw, ra, dr, na, dn, qx, qy,
                                       u, tm, fu, gu, fm, gm),
                         _arc_min_cell(code, R, rc, plane, ca, cb, th0, sw, ra, dr, na, dn, qx, qy,
                                       tm, v, fm, gm, fv, gv))
            else:
                if not ina:
                    u = _arc_reach_end(code, R, rc, plane, ca, cb, th0, sw, ra, dr, na, dn, qx, qy, b, a)
                    fu, gu, _, zu = _arc_f(code, R, rc, plane, ca, cb, th0, sw, ra, dr, na, dn, u, qx, qy)
                if not inb:
                    v = _arc_reach_end(code, R, rc, plane, ca, cb, th0, sw, ra, dr, na, dn, qx, qy, a, b)
                    fv, gv, _, zv = _arc_f(code, R, rc, plane, ca, cb, th0, sw, ra, dr, na, dn, v, qx, qy)
                lo = _arc_min_cell(code, R, rc, plane, ca, cb, th0, sw, ra, dr, na, dn, qx, qy,
                                   u, v, fu, gu, fv, gv)
            hi = max(zu, zv) + L
            if lo < run_lo:
                run_lo = lo
            if hi > run_hi:
                run_hi = hi
            if tm >= 0.0:  # reached inside the cell only: a run of its own
                cnt = _push_interval(out, cnt, run_lo, run_hi)
                run_lo = np.inf
                run_hi = -np.inf
        if not inb and run_lo < np.inf:
            cnt = _push_interval(out, cnt, run_lo, run_hi)
            run_lo = np.inf
            run_hi = -np.inf
        fa, ga, da, za = fb, gb, db, zb
    if run_lo < np.inf:
        cnt = _push_interval(out, cnt, run_lo, run_hi)
    return cnt


@njit(cache=True)
def _push_interval(out, cnt, lo, hi):
    """Add [lo, hi] to the sorted disjoint rows ``out[:cnt]``, merging overlaps."""
    # insert keeping order by lo, then merge
    k = cnt
    if k == out.shape[0]:  # full: merge into the nearest row (a helix of >64 far-apart turns)
        k -= 1
        lo = min(lo, out[k, 0])
        hi = max(hi, out[k, 1])
    out[k, 0] = lo
    out[k, 1] = hi
    k += 1
    i = k - 1
    while i > 0 and out[i - 1, 0] > out[i, 0]:
        a0, a1 = out[i - 1, 0], out[i - 1, 1]
        out[i - 1, 0], out[i - 1, 1] = out[i, 0], out[i, 1]
        out[i, 0], out[i, 1] = a0, a1
        i -= 1
    m = 0
    for j in range(k):
        if m > 0 and out[j, 0] <= out[m - 1, 1]:
            if out[j, 1] > out[m - 1, 1]:
                out[m - 1, 1] = out[j, 1]
        else:
            out[m, 0] = out[j, 0]
            out[m, 1] = out[j, 1]
            m += 1
    return m


@njit(cache=True)
def arc_box(plane, ca, cb, th0, sw, ra, rb, na, nb, t0, t1):
    """xy bounding box ``(xmin, xmax, ymin, ymax)`` of the tip over an arc piece."""
    dr = rb - ra
    dn = nb - na
    x, y, _, _, _, _ = _arc_point(plane, ca, cb, th0, sw, ra, dr, na, dn, t0)
    xmin = xmax = x
    ymin = ymax = y
    x, y, _, _, _, _ = _arc_point(plane, ca, cb, th0, sw, ra, dr, na, dn, t1)
    xmin = min(xmin, x)
    xmax = max(xmax, x)
    ymin = min(ymin, y)
    ymax = max(ymax, y)
    if sw != 0.0:
        a = th0 + sw * t0
        b = th0 + sw * t1
        lo = min(a, b)
        hi = max(a, b)
        k = math.ceil(lo / _HALF_PI)
        ang = k * _HALF_PI
        while ang < hi:
            t = (ang - th0) / sw
            x, y, _, _, _, _ = _arc_point(plane, ca, cb, th0, sw, ra, dr, na, dn, t)
            xmin = min(xmin, x)
            xmax = max(xmax, x)
            ymin = min(ymin, y)
            ymax = max(ymax, y)
            ang += _HALF_PI
            if ang - lo > 8.0 * math.pi * 1e6:  # absurd sweeps: the box of the whole circle
                break
    # the radius is linear in t: the extremes above used the radius at their angle;
    # a tiny margin covers rounding
    eps = 1e-9 * (1.0 + abs(xmin) + abs(xmax) + abs(ymin) + abs(ymax))
    return xmin - eps, xmax + eps, ymin - eps, ymax + eps


@njit(cache=True)
def piece_rays(kind, code, R, rc, L, g, t0, t1, qx, qy, out, ts):
    """Intervals removed from ray (qx, qy) by one piece; returns their count.

    ``kind``: NO_CUT, STAMP (``g[0:3]`` the tip), LINE (``g[0:3]`` start, ``g[3:6]`` end,
    cut from ``t0`` to ``t1``) or an arc's plane 17/18/19 (``g`` = ca, cb, theta_a, sweep,
    r_a, r_b, n_a, n_b).
    """
    if kind == NO_CUT:
        return 0
    if kind == STAMP:
        d = math.sqrt((qx - g[0]) ** 2 + (qy - g[1]) ** 2)
        if d > R:
            return 0
        out[0, 0] = g[2] + _envelope(code, R, rc, d)
        out[0, 1] = g[2] + L
        return 1
    if kind == LINE:
        return line_ray(code, R, rc, L, g, t0, t1, qx, qy, out[0])
    return arc_ray(code, R, rc, L, kind, g[0], g[1], g[2], g[3], g[4], g[5], g[6], g[7], t0, t1,
                   qx, qy, out, ts)


@njit(cache=True)
def piece_box(kind, g, t0, t1):
    """xy bounding box ``(xmin, xmax, ymin, ymax)`` of the tip over one piece."""
    if kind == STAMP or kind == NO_CUT:
        return g[0], g[0], g[1], g[1]
    if kind == LINE:
        xa = g[0] + (g[3] - g[0]) * t0
        ya = g[1] + (g[4] - g[1]) * t0
        xb = g[0] + (g[3] - g[0]) * t1
        yb = g[1] + (g[4] - g[1]) * t1
        return min(xa, xb), max(xa, xb), min(ya, yb), max(ya, yb)
    return arc_box(kind, g[0], g[1], g[2], g[3], g[4], g[5], g[6], g[7], t0, t1)
