"""The exact top of a cut stock at a few rays, by dense sampling of the program's path.

An independent check of the simulator's exact sweep for the benchmark: it shares no code
with :mod:`zmap.sim._sweep_kernels`, :mod:`zmap.sim.pieces` or :mod:`zmap.sim.path`; only the
parsed moves (:func:`zmap.sim.gcode.parse`) and the cutters' dimensions come from zmap. The
cutter's envelope, the path of a line or an arc (from its start, end, centre, plane and
signed sweep) and the search are written here in plain numpy (the tests use them too,
through ``tests/zmap/sim/sweep_reference.py``): the path is sampled every 1 um, and the
best sample refined three times, each by sampling 1000 times finer around the best so far.

For speed, at a ray ``(qx, qy)`` only the moves whose xy box grown by their tool's radius
holds the ray are swept; a line's parameter is first clipped to where its axis passes within
the tool's radius of the ray, the lines of one ray are sampled together, and moves are taken
lowest bound first, stopping once a move's bound is above the material left (a line's sweep
is no lower than its lowest tip there lifted by the envelope at its closest approach, an
arc's no lower than its lowest tip). A line is refined only where its bottom may be the
lowest: along a line the bottom is convex in the parameter (the cutter is convex), so it
lies within one sample of the best sample and at most the rise to the other neighbour below
it.

A move cuts when its start is known (``known & 7 == 7``) and it has a length; rapids cut too.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["PLANES", "envelope", "line_path", "arc_path", "sweep_interval", "RayReference"]

# in-plane first axis, second axis, normal axis (LinuxCNC: G18 is (Z, X), G19 (Y, Z))
PLANES = {17: (0, 1, 2), 18: (2, 0, 1), 19: (1, 2, 0)}
STEP = 1e-3  # mm between samples of the path
FINE = 2001  # samples of each refinement round (1000 times finer)


def _corner(kind: str, radius: float, corner: float) -> float:
    return 0.0 if kind == "flat" else (radius if kind == "ball" else corner)


def envelope(radius: Any, corner: Any, r: np.ndarray) -> np.ndarray:
    """Height of a cutter's bottom above its tip at radial distance ``r``; inf beyond the
    radius. ``corner`` is 0 for flat, the radius for ball, the corner radius for bull;
    ``radius`` and ``corner`` broadcast with ``r``."""
    r = np.asarray(r, dtype=np.float64)
    radius = np.broadcast_to(np.asarray(radius, dtype=np.float64), r.shape)
    corner = np.broadcast_to(np.asarray(corner, dtype=np.float64), r.shape)
    d = np.maximum(r - (radius - corner), 0.0)
    h = corner - np.sqrt(np.maximum(corner * corner - d * d, 0.0))
    return np.where(r <= radius, h, np.inf)


def line_path(start, end):
    """Tip at parameter t in [0, 1] of a straight move, and its length."""
    s = np.asarray(start, dtype=np.float64)
    e = np.asarray(end, dtype=np.float64)

    def at(t):
        return s + (e - s) * np.asarray(t, dtype=np.float64)[:, None]

    return at, float(np.linalg.norm(e - s))


def arc_path(start, end, center, plane, sweep):
    """Tip at parameter t of an arc or helix (angle, radius, normal coordinate linear in t)."""
    a, b, n = PLANES[int(plane)]
    s = np.asarray(start, dtype=np.float64)
    e = np.asarray(end, dtype=np.float64)
    c = np.asarray(center, dtype=np.float64)
    th0 = np.arctan2(s[b] - c[b], s[a] - c[a])
    r0 = np.hypot(s[a] - c[a], s[b] - c[b])
    r1 = np.hypot(e[a] - c[a], e[b] - c[b])

    def at(t):
        t = np.asarray(t, dtype=np.float64)
        th = th0 + sweep * t
        rad = r0 + (r1 - r0) * t
        p = np.empty((t.shape[0], 3))
        p[:, a] = c[a] + rad * np.cos(th)
        p[:, b] = c[b] + rad * np.sin(th)
        p[:, n] = s[n] + (e[n] - s[n]) * t
        return p

    length = float(np.hypot(abs(sweep) * max(r0, r1), e[n] - s[n]) + abs(r1 - r0))
    return at, length


def sweep_interval(at, length, cutter, qx, qy, t0=0.0, t1=1.0, step=STEP):
    """``(bottom, top)`` of the material the cutter removes from ray (qx, qy) along
    ``at(t)``, t in [t0, t1]; ``(inf, -inf)`` where it never reaches the ray."""
    R, L = float(cutter.radius), float(cutter.length)
    c = _corner(cutter.kind, R, float(cutter.corner_radius))
    n = max(int(np.ceil(length * (t1 - t0) / step)), 1) + 1
    t = np.linspace(t0, t1, n)

    def bottom(tt):
        p = at(tt)
        return p[:, 2] + envelope(R, c, np.hypot(p[:, 0] - qx, p[:, 1] - qy)), p

    f, p = bottom(t)
    reach = np.isfinite(f)
    if not reach.any():
        # the reach may lie between two samples: look finer around the nearest one
        d = np.hypot(p[:, 0] - qx, p[:, 1] - qy)
        k = int(np.argmin(d))
        if d[k] > R + step:
            return np.inf, -np.inf
        f, p = bottom(np.linspace(t[max(k - 1, 0)], t[min(k + 1, n - 1)], FINE))
        reach = np.isfinite(f)
        if not reach.any():
            return np.inf, -np.inf
        return float(f.min()), float(p[reach, 2].max() + L)
    top = float(p[reach, 2].max() + L)
    best = float(f.min())
    for _ in range(3):  # each round 1000 times finer around the best sample so far
        k = int(np.argmin(f))
        t = np.linspace(t[max(k - 1, 0)], t[min(k + 1, t.shape[0] - 1)], FINE)
        f, _ = bottom(t)
        best = min(best, float(f.min()))
    return best, top


def _lines_interval(S, E, t0, t1, R, C, L, qx, qy, cap=np.inf, step=STEP):
    """:func:`sweep_interval` of many lines at one ray at once: ``(bottom, top)`` per line.

    Only the lines whose bottom may be the lowest of all and below ``cap`` are refined: the
    bottom along a line is convex in its parameter (the cutter is convex), so it lies at
    most one sample from the best sample and drops below it by at most the rise to the
    neighbour on the other side. The others keep their best sample, above the lowest bottom.
    """
    m = S.shape[0]
    D = E - S
    n = np.maximum(np.ceil(np.linalg.norm(D, axis=1) * (t1 - t0) / step), 1).astype(np.int64) + 1
    first = np.cumsum(n) - n
    g = np.repeat(np.arange(m), n)
    t = np.arange(int(n.sum()), dtype=np.float64) - np.repeat(first, n)
    t *= np.repeat((t1 - t0) / (n - 1), n)
    t += np.repeat(t0, n)
    px = np.repeat(S[:, 0], n) + np.repeat(D[:, 0], n) * t
    py = np.repeat(S[:, 1], n) + np.repeat(D[:, 1], n) * t
    pz = np.repeat(S[:, 2], n) + np.repeat(D[:, 2], n) * t
    dist = np.hypot(px - qx, py - qy)
    f = pz + envelope(np.repeat(R, n), np.repeat(C, n), dist)
    reach = np.isfinite(f)
    top = np.maximum.reduceat(np.where(reach, pz, -np.inf), first) + L
    best = np.minimum.reduceat(f, first)
    # the bracket of each line's next round: around its best sample, or around the sample
    # nearest the ray where none reaches it (the reach may lie between two samples)
    found = np.isfinite(best)
    key = np.where(found[g], f, dist)
    at = np.flatnonzero(key == np.repeat(np.minimum.reduceat(key, first), n))
    k = at[np.searchsorted(at, first)]  # the first best sample of each line
    has_lo, has_hi = k > first, k < first + n - 1
    lo = t[np.where(has_lo, k - 1, k)]
    hi = t[np.where(has_hi, k + 1, k)]
    near = ~found & (np.minimum.reduceat(dist, first) <= R + step)
    # how far below its best sample a line's bottom may lie (convexity): on each side of
    # the best sample, the rise to the neighbour on the other side; unbounded without it
    f_lo = np.where(has_lo, f[np.maximum(k - 1, 0)], np.inf)
    f_hi = np.where(has_hi, f[np.minimum(k + 1, f.size - 1)], np.inf)
    fk = f[k]
    with np.errstate(invalid="ignore"):
        drop = np.maximum(np.where(has_hi, f_lo - fk, 0.0), np.where(has_lo, f_hi - fk, 0.0))
        drop = np.where(np.isnan(drop), np.inf, drop)
        may = found & (fk - drop < min(cap, float(best[found].min()) if found.any() else np.inf))
    rounds = np.where(may, 3, np.where(near, 1, 0))
    for r in range(3):
        act = np.flatnonzero(rounds > r)
        if act.size == 0:
            break
        tt = lo[act, None] + (hi - lo)[act, None] * np.linspace(0.0, 1.0, FINE)[None, :]
        pp = S[act, None, :] + D[act, None, :] * tt[:, :, None]
        ff = pp[:, :, 2] + envelope(R[act, None], C[act, None],
                                    np.hypot(pp[:, :, 0] - qx, pp[:, :, 1] - qy))
        kk = np.argmin(ff, axis=1)
        got = ff[np.arange(act.size), kk]
        newly = ~found[act] & np.isfinite(got)
        if newly.any():  # first reach found between two samples: its top, as the reference
            rows = act[newly]
            zz = np.where(np.isfinite(ff[newly]), pp[newly, :, 2], -np.inf).max(axis=1)
            top[rows] = zz + L[rows]
        best[act] = np.minimum(best[act], got)
        lo[act] = tt[np.arange(act.size), np.maximum(kk - 1, 0)]
        hi[act] = tt[np.arange(act.size), np.minimum(kk + 1, FINE - 1)]
    bad = ~np.isfinite(best)
    top[bad] = -np.inf
    return best, top


class RayReference:
    """The reference top of a stock box cut by a program, at any ray.

    Parameters
    ----------
    moves : ndarray of zmap.sim.gcode.MOVE_DTYPE
        The program's moves (mm).
    cutters : dict of int to Cutter
        The cutter of each tool number.
    default : Cutter or None
        The cutter of tool numbers not in ``cutters``.
    stock : 6 floats
        The box ``(x0, y0, z0, x1, y1, z1)``; each ray starts as ``[z0, z1]``.
    """

    def __init__(self, moves: np.ndarray, cutters: dict, default: Any, stock) -> None:
        s, e = moves["start"].astype(np.float64), moves["end"].astype(np.float64)
        arc = moves["kind"] >= 2
        cut = ((moves["known"] & 7) == 7) & (arc | (np.abs(e - s).max(axis=1) > 0))
        idx = np.flatnonzero(cut)
        self.moves = moves[idx]
        self.index = idx
        tools = [cutters.get(int(t), default) for t in self.moves["tool"]]
        if any(c is None for c in tools):
            raise ValueError("a cutting move's tool is in neither the tool table nor the default")
        self.cutter = tools
        self.R = np.array([c.radius for c in tools])
        self.C = np.array([_corner(c.kind, c.radius, c.corner_radius) for c in tools])
        self.L = np.array([c.length for c in tools])
        self.stock = tuple(float(v) for v in stock)
        m = self.moves
        s, e = m["start"].astype(np.float64), m["end"].astype(np.float64)
        self.S, self.E = s, e
        self.arc = m["kind"] >= 2
        lo = np.minimum(s, e)
        hi = np.maximum(s, e)
        # arcs: the whole circle of the larger radius in-plane (conservative), the normal
        # coordinate between its ends
        for i in np.flatnonzero(self.arc):
            a, b, _ = PLANES[int(m["plane"][i])]
            c = m["center"][i]
            rad = max(np.hypot(s[i, a] - c[a], s[i, b] - c[b]), np.hypot(e[i, a] - c[a], e[i, b] - c[b]))
            for ax in (a, b):
                lo[i, ax] = c[ax] - rad
                hi[i, ax] = c[ax] + rad
        self.zmin = lo[:, 2]
        self.box = np.column_stack([lo[:, 0] - self.R, lo[:, 1] - self.R, hi[:, 0] + self.R, hi[:, 1] + self.R])

    def near(self, qx: float, qy: float) -> np.ndarray:
        """Rows of the moves whose grown xy box holds the ray."""
        b = self.box
        return np.flatnonzero((b[:, 0] <= qx) & (qx <= b[:, 2]) & (b[:, 1] <= qy) & (qy <= b[:, 3]))

    def _line_reach(self, rows: np.ndarray, qx: float, qy: float):
        """Which lines pass within R of the ray, the parameter range where they do (padded
        by two steps), and their closest approach."""
        S, D = self.S[rows], self.E[rows] - self.S[rows]
        R = self.R[rows]
        a = D[:, 0] ** 2 + D[:, 1] ** 2
        bx, by = S[:, 0] - qx, S[:, 1] - qy
        b = 2.0 * (bx * D[:, 0] + by * D[:, 1])
        c = bx * bx + by * by - (R + 2 * STEP) ** 2
        t0 = np.zeros(rows.size)
        t1 = np.ones(rows.size)
        ok = np.ones(rows.size, dtype=bool)
        flat = a < 1e-24
        ok[flat] = c[flat] <= 0.0
        m = ~flat
        disc = b[m] ** 2 - 4.0 * a[m] * c[m]
        ok[m] = disc >= 0.0
        sq = np.sqrt(np.maximum(disc, 0.0))
        t0[m] = np.clip((-b[m] - sq) / (2.0 * a[m]), 0.0, 1.0)
        t1[m] = np.clip((-b[m] + sq) / (2.0 * a[m]), 0.0, 1.0)
        ok &= t1 >= t0
        ts = np.where(flat, 0.0, np.clip(-b / (2.0 * np.where(flat, 1.0, a)), 0.0, 1.0))
        dmin = np.hypot(bx + D[:, 0] * ts, by + D[:, 1] * ts)  # closest approach to the ray
        return ok, t0, t1, dmin

    def top(self, qx: float, qy: float, chunk: int = 16) -> tuple[float, int]:
        """Top of the material left at ray ``(qx, qy)`` (NaN where none is left), and the
        source line of the move whose sweep made it (0 where the stock's top is left)."""
        z0, z1 = self.stock[2], self.stock[5]
        left = [(z0, z1)]  # material along the ray, bottom up
        who = 0
        rows = self.near(qx, qy)
        # a line's sweep is no lower than its lowest tip where it reaches the ray (lines are
        # linear in z) lifted by the cutter's envelope at its closest approach; an arc's no
        # lower than its lowest tip
        lines = rows[~self.arc[rows]]
        ok, t0, t1, dmin = self._line_reach(lines, qx, qy)
        lines, t0, t1, dmin = lines[ok], t0[ok], t1[ok], dmin[ok]
        sz, dz = self.S[lines, 2], self.E[lines, 2] - self.S[lines, 2]
        lift = envelope(self.R[lines], self.C[lines], np.minimum(dmin, self.R[lines]))
        arcs = rows[self.arc[rows]]
        rows = np.concatenate([lines, arcs])
        ta = np.concatenate([t0, np.zeros(arcs.size)])
        tb = np.concatenate([t1, np.ones(arcs.size)])
        zlo = np.concatenate([np.minimum(sz + dz * t0, sz + dz * t1) + lift, self.zmin[arcs]])
        order = np.argsort(zlo, kind="stable")
        rows, ta, tb, zlo = rows[order], ta[order], tb[order], zlo[order]
        while rows.size and left:
            keep = zlo < left[-1][1]  # the others cannot lower the top
            rows, ta, tb, zlo = rows[keep], ta[keep], tb[keep], zlo[keep]
            batch, ba, bb = rows[:chunk], ta[:chunk], tb[:chunk]
            rows, ta, tb, zlo = rows[chunk:], ta[chunk:], tb[chunk:], zlo[chunk:]
            if batch.size == 0:
                break
            got: list[tuple[float, float, int]] = []
            is_line = ~self.arc[batch]
            if is_line.any():
                lb = batch[is_line]
                bot, tp = _lines_interval(self.S[lb], self.E[lb], ba[is_line], bb[is_line], self.R[lb],
                                          self.C[lb], self.L[lb], qx, qy, cap=left[-1][1])
                got += [(float(u), float(v), int(w)) for u, v, w in zip(bot, tp, lb)]
            for i in batch[self.arc[batch]]:
                m = self.moves[i]
                at, length = arc_path(m["start"], m["end"], m["center"], m["plane"], float(m["sweep"]))
                u, v = sweep_interval(at, length, self.cutter[i], qx, qy)
                got.append((u, v, int(i)))
            for u, v, i in got:
                if not u < v:
                    continue
                before = left[-1][1] if left else None
                left = _subtract(left, u, v)
                after = left[-1][1] if left else None
                if after != before:
                    who = int(self.moves["line"][i])
        return (left[-1][1] if left else float("nan")), who


def _subtract(left: list, u: float, v: float) -> list:
    out = []
    for a, b in left:
        if v <= a or u >= b:
            out.append((a, b))
            continue
        if a < u:
            out.append((a, u))
        if v < b:
            out.append((v, b))
    return out
