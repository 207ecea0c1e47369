"""Slow, obvious references of :mod:`zmap.cam` for tests and the benchmark.

:func:`drop_cutter_reference` is a brute-force drop: every point of a lattice of spacing ``h``
over the cutter's disk plus points every ``h`` along its rim, then two finer lattices (``h/20``
then ``h/400``) over the square around the best point so far, clipped to the disk. No
pruning, no pyramid, no pattern search: only ``max(height - envelope)`` over many points.
"""

from __future__ import annotations

import numpy as np

__all__ = ["drop_cutter_reference"]


def drop_cutter_reference(heights, cutter, x, y, *, h: float = 0.01, levels: int = 2) -> np.ndarray:
    """CL heights by exhaustive search (one point at a time; slow: for tests and benches).

    Parameters
    ----------
    heights : callable ``heights(x, y)`` — exact surface heights in mm (NaN: no surface).
    cutter : zmap.sim.tools.Cutter
    x, y : array_like of float — axis positions (mm), same shape.
    h : float — coarse lattice spacing, mm.
    levels : int — finer lattices after the coarse one (each 20x finer).
    """
    x = np.atleast_1d(np.asarray(x, dtype=np.float64))
    y = np.atleast_1d(np.asarray(y, dtype=np.float64))
    R = cutter.radius
    n = int(np.ceil(R / h))
    a = np.arange(-n, n + 1) * h
    LX, LY = np.meshgrid(a, a, indexing="ij")
    keep = LX ** 2 + LY ** 2 <= R * R
    lx, ly = LX[keep], LY[keep]
    m = max(16, int(np.ceil(2 * np.pi * R / h)))
    th = 2 * np.pi * np.arange(m) / m
    lx = np.concatenate([lx, R * np.cos(th)])
    ly = np.concatenate([ly, R * np.sin(th)])
    out = np.empty(x.size)
    for k in range(x.size):
        g = _g(heights, cutter, x[k], y[k], x[k] + lx, y[k] + ly)
        b = int(np.argmax(g))
        bx, by, bg = lx[b], ly[b], g[b]
        step = h
        for _ in range(levels):
            fine = np.linspace(-step, step, 41)
            FX, FY = np.meshgrid(fine, fine, indexing="ij")
            cx, cy = bx + FX.ravel(), by + FY.ravel()
            r = np.hypot(cx, cy)
            f = np.where(r > R, R / np.maximum(r, 1e-300), 1.0)
            cx, cy = cx * f, cy * f
            g = _g(heights, cutter, x[k], y[k], x[k] + cx, y[k] + cy)
            b = int(np.argmax(g))
            if g[b] > bg:
                bx, by, bg = cx[b], cy[b], g[b]
            step = step / 20
        out[k] = bg if np.isfinite(bg) else np.nan
    return out


def _g(heights, cutter, qx, qy, ux, uy):
    z = np.asarray(heights(ux, uy), dtype=np.float64)
    env = cutter.lower_envelope(np.hypot(ux - qx, uy - qy))
    g = z - env
    g[~np.isfinite(g)] = -np.inf
    return g


def drop_cutter_reference_dense(heights, cutter, x, y, *, h: float = 0.005, rim_h: float | None = None,
                                sub: int = 5, xtol: float = 1e-8, max_cand: int = 400, keep: int = 60,
                                max_iter: int = 200, n_seg: int = 24, chunk: int = 400_000) -> np.ndarray:
    """CL heights by a dense lattice and refinement around every candidate (slow; benches).

    Shares nothing with the fast path but ``heights``: per axis, ``g(u) = heights(u) -
    envelope(|u - axis|)`` on a lattice of spacing ``h`` over the whole disk and on the rim as
    a curve (a point every ``rim_h``, default ``h / 4``). Every lattice or rim point whose
    bound ``g + max |g - g(neighbour)|`` (its 8 lattice neighbours; its 2 rim neighbours and
    the nearest lattice point for a rim point) reaches the best ``g`` found is a candidate, not
    only the best one (up to ``max_cand``, highest ``g`` first). Around each candidate a
    ``(2*sub + 1)^2`` lattice of spacing ``s / sub`` (``s`` the spacing so far; points off the
    disk projected onto the rim, so the rim is followed too), and again with the new
    candidates (the ``keep`` highest, and the best points of the ``keep`` best windows, with
    the same bound: the leading candidates' lineages live on); while the best still rises,
    the windows keep their size and walk on (a contact sliding along a crease), then the
    spacing shrinks, down to ``xtol`` (at most ``max_iter`` rounds). Each round, the best
    point of each of the ``n_seg`` best windows is also searched along the segments to its
    8 neighbours (golden section: a crease or a jump that the lattice straddles is met on
    it); without that a lattice walk stalls on a curved
    crease 1e-5 to 1e-4 mm short of its top (tests/zmap/cam/test_reference.py).
    Every value is an exact contact of a surface point under the cutter: a lower bound of
    the true CL, tight up to the features narrower than the lattice that no candidate's
    bound points at (on the tests' rim slivers and wiggly crests, within 1e-9 mm).

    Parameters
    ----------
    heights : callable ``heights(x, y)`` — exact heights in mm (NaN: no surface).
    cutter : zmap.sim.tools.Cutter
    x, y : array_like of float — axis positions (mm), same shape.
    h : float — spacing of the lattice on the disk, mm.
    rim_h : float, optional — arc spacing of the rim points, mm (default ``h / 4``).
    sub : int — each refinement level divides the spacing by ``sub``.
    xtol : float — the last level's spacing, mm.
    max_cand, keep : int — candidates refined at the first level and at each later one.
    max_iter : int — rounds of windows at most.
    n_seg : int — windows whose best point is searched along the segments, per round.
    chunk : int — heights per call.

    Returns
    -------
    ndarray, float64 — CL heights (NaN: no surface under the cutter).
    """
    x = np.atleast_1d(np.asarray(x, dtype=np.float64)).ravel()
    y = np.atleast_1d(np.asarray(y, dtype=np.float64)).ravel()
    R = cutter.radius
    rim_h = h / 4 if rim_h is None else rim_h
    n = int(np.ceil(R / h))
    a = np.arange(-n, n + 1) * h
    LX, LY = np.meshgrid(a, a, indexing="ij")
    inside = LX ** 2 + LY ** 2 <= R * R
    m = max(16, int(np.ceil(2 * np.pi * R / rim_h)))
    th = 2 * np.pi * np.arange(m) / m
    rx, ry = R * np.cos(th), R * np.sin(th)
    # the lattice point nearest each rim point (inside the disk)
    ri = np.clip(np.round(rx / h).astype(int) + n, 0, 2 * n)
    rj = np.clip(np.round(ry / h).astype(int) + n, 0, 2 * n)
    o = np.arange(-sub, sub + 1)
    SX, SY = np.meshgrid(o, o, indexing="ij")
    SX, SY = SX.ravel().astype(float), SY.ravel().astype(float)
    out = np.empty(x.size)
    for k in range(x.size):
        qx, qy = x[k], y[k]
        lx, ly = LX[inside], LY[inside]
        gl = np.concatenate([_g(heights, cutter, qx, qy, qx + lx[s:s + chunk], qy + ly[s:s + chunk])
                             for s in range(0, lx.size, chunk)])
        G = np.full(LX.shape, -np.inf)
        G[inside] = gl
        gr = _g(heights, cutter, qx, qy, qx + rx, qy + ry)
        best = max(np.max(gl), np.max(gr))
        if not np.isfinite(best):
            out[k] = np.nan
            continue
        # bounds: g + the largest |difference| to a finite neighbour
        P = np.pad(G, 1, constant_values=-np.inf)
        dmax = np.zeros(G.shape)
        for da in (-1, 0, 1):
            for db in (-1, 0, 1):
                if da or db:
                    Nb = P[1 + da:1 + da + G.shape[0], 1 + db:1 + db + G.shape[1]]
                    fin = np.isfinite(Nb) & np.isfinite(G)
                    with np.errstate(invalid="ignore"):
                        dmax = np.where(fin, np.maximum(dmax, np.abs(G - Nb)), dmax)
        ubl = G + dmax
        gnl = G[ri, rj]
        with np.errstate(invalid="ignore"):
            dr = np.maximum(np.abs(gr - np.roll(gr, 1)), np.abs(gr - np.roll(gr, -1)))
            dr = np.where(np.isfinite(dr), dr, 0.0)
            dr = np.maximum(dr, np.where(np.isfinite(gnl) & np.isfinite(gr), np.abs(gr - gnl), 0.0))
        ubr = gr + dr
        cx = np.concatenate([LX[ubl >= best], rx[ubr >= best]])
        cy = np.concatenate([LY[ubl >= best], ry[ubr >= best]])
        cg = np.concatenate([G[ubl >= best], gr[ubr >= best]])
        cs = np.concatenate([np.full(int((ubl >= best).sum()), h), np.full(int((ubr >= best).sum()), rim_h)])
        order = np.argsort(-cg, kind="stable")[:max_cand]
        cx, cy, cs = cx[order], cy[order], cs[order]
        it = 0
        while cx.size and it < max_iter:
            it += 1
            step = cs / sub
            px = (cx[:, None] + step[:, None] * SX[None, :])
            py = (cy[:, None] + step[:, None] * SY[None, :])
            r = np.hypot(px, py)
            f = np.where(r > R, R / np.maximum(r, 1e-300), 1.0)
            px, py = px * f, py * f
            g = _g(heights, cutter, qx, qy, qx + px, qy + py)
            # each window's best point, searched along the segments to its 8 neighbours
            # (golden section: onto the crease or the jump between them, which a lattice
            # only straddles)
            # (the ``n_seg`` windows with the highest best points)
            wb = np.argmax(g, axis=1)
            rr_ = np.arange(g.shape[0])
            rr_ = rr_[np.argsort(-g[rr_, wb], kind="stable")[:n_seg]]
            wb_ = wb[rr_]
            bx_, by_, bg_ = px[rr_, wb_], py[rr_, wb_], g[rr_, wb_]
            lx_, ly_, lg_ = _segments(heights, cutter, qx, qy, bx_, by_, step[rr_], R)
            better = lg_ > bg_
            px[rr_[better], wb_[better]] = lx_[better]
            py[rr_[better], wb_[better]] = ly_[better]
            g[rr_[better], wb_[better]] = lg_[better]
            gbest = float(np.max(g))
            moved = gbest > best + 1e-13
            best = max(best, gbest)
            if not moved and step.max() < xtol:
                break
            # candidates of this level: the sub-lattice points whose bound reaches the best
            Gs = g.reshape(-1, 2 * sub + 1, 2 * sub + 1)
            Pp = np.pad(Gs, ((0, 0), (1, 1), (1, 1)), constant_values=-np.inf)
            dm = np.zeros(Gs.shape)
            for da in (-1, 0, 1):
                for db in (-1, 0, 1):
                    if da or db:
                        Nb = Pp[:, 1 + da:1 + da + Gs.shape[1], 1 + db:1 + db + Gs.shape[2]]
                        fin = np.isfinite(Nb) & np.isfinite(Gs)
                        with np.errstate(invalid="ignore"):
                            dm = np.where(fin, np.maximum(dm, np.abs(Gs - Nb)), dm)
            ub = (Gs + dm).reshape(g.shape)
            sel = np.flatnonzero((ub >= best).ravel())
            sel = sel[np.argsort(-g.ravel()[sel], kind="stable")[:keep]]
            # and every window's own best point where its bound reaches the best: each
            # candidate's lineage lives on (a lower local maximum now may win finer)
            wb = np.argmax(g, axis=1)
            wsel = np.arange(g.shape[0]) * g.shape[1] + wb
            wsel = wsel[ub.ravel()[wsel] >= best]
            wsel = wsel[np.argsort(-g.ravel()[wsel], kind="stable")[:keep]]
            sel = np.unique(np.concatenate([sel, wsel]))
            # windows that overlap (points closer than half a step) are one
            key = np.stack([np.round(px.ravel()[sel] / (0.5 * np.repeat(step, g.shape[1])[sel])),
                            np.round(py.ravel()[sel] / (0.5 * np.repeat(step, g.shape[1])[sel]))], axis=1)
            _u, first = np.unique(key, axis=0, return_index=True)
            sel = sel[np.sort(first)]
            cx, cy = px.ravel()[sel], py.ravel()[sel]
            # while the best still moves (along a crease), windows of the same size walk on;
            # then the next level, finer
            cs = np.repeat(cs if moved else step, g.shape[1])[sel]
        out[k] = best
    return out


def _segments(heights, cutter, qx, qy, bx, by, step, R, iters=30):
    """Per point ``(bx[k], by[k])``: the best ``g`` on the 8 segments to its lattice
    neighbours ``step[k]`` away (golden section on each; points off the disk projected onto
    the rim)."""
    gold = 0.6180339887498949
    d8 = np.array([[1, 0], [-1, 0], [0, 1], [0, -1], [1, 1], [-1, 1], [1, -1], [-1, -1]], dtype=np.float64)
    ax = np.repeat(bx, 8)
    ay = np.repeat(by, 8)
    ex = np.tile(d8[:, 0], bx.size) * np.repeat(step, 8)
    ey = np.tile(d8[:, 1], bx.size) * np.repeat(step, 8)

    def at(t):
        cx, cy = ax + t * ex, ay + t * ey
        r = np.hypot(cx, cy)
        f = np.where(r > R, R / np.maximum(r, 1e-300), 1.0)
        cx, cy = cx * f, cy * f
        return cx, cy, _g(heights, cutter, qx, qy, qx + cx, qy + cy)

    lo = np.zeros(ax.size)
    hi = np.ones(ax.size)
    t1 = hi - gold * (hi - lo)
    t2 = lo + gold * (hi - lo)
    x1, y1, g1 = at(t1)
    x2, y2, g2 = at(t2)
    bxs, bys, bgs = x1.copy(), y1.copy(), g1.copy()
    for _ in range(iters):
        up = g2 > bgs
        bxs[up], bys[up], bgs[up] = x2[up], y2[up], g2[up]
        left = g1 >= g2  # keep [lo, t2]
        hi = np.where(left, t2, hi)
        lo = np.where(left, lo, t1)
        nt1 = np.where(left, hi - gold * (hi - lo), t2)
        nt2 = np.where(left, t1, lo + gold * (hi - lo))
        nx1, ny1, ng1 = at(nt1)
        nx2, ny2, ng2 = at(nt2)
        x1, y1, g1 = nx1, ny1, ng1
        x2, y2, g2 = nx2, ny2, ng2
        t1, t2 = nt1, nt2
        up = g1 > bgs
        bxs[up], bys[up], bgs[up] = x1[up], y1[up], g1[up]
    k = np.argmax(bgs.reshape(-1, 8), axis=1)
    r_ = np.arange(bx.size) * 8 + k
    return bxs[r_], bys[r_], bgs[r_]
