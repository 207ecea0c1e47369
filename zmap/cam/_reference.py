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
