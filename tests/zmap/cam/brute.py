"""An independent drop-cutter over a z-map for the tests: shares no code with zmap.cam."""

from __future__ import annotations

import numpy as np

from zmap.interpolate import bezier


def _env(c, d):
    return c.lower_envelope(np.asarray(d, dtype=float))


def brute_zmap(zm, c, x, y, h=0.01):
    """Independent CL over a z-map: every node under the cutter and the Bezier surface
    (:func:`zmap.interpolate.bezier`) on an ``h`` lattice over the disk and its rim."""
    R = c.radius
    g = np.arange(-R, R + h / 2, h)
    U, V = np.meshgrid(g, g, indexing="ij")
    m = U * U + V * V <= R * R
    th = np.linspace(0, 2 * np.pi, int(2 * np.pi * R / h), endpoint=False)
    U = np.r_[U[m], R * np.cos(th)]
    V = np.r_[V[m], R * np.sin(th)]
    env = np.nan_to_num(_env(c, np.minimum(np.hypot(U, V), R)), nan=np.inf)
    nx, ny = zm.z.shape
    out = np.empty(len(x))
    for k, (qx, qy) in enumerate(zip(x, y)):
        hh = bezier(zm, qx + U, qy + V)
        best = np.nanmax(hh - env) if np.isfinite(hh).any() else -np.inf
        i = np.arange(max(0, int(np.ceil((qx - R - zm.x0) / zm.dx))), min(nx, int((qx + R - zm.x0) / zm.dx) + 1))
        j = np.arange(max(0, int(np.ceil((qy - R - zm.y0) / zm.dy))), min(ny, int((qy + R - zm.y0) / zm.dy) + 1))
        I, J = np.meshgrid(i, j, indexing="ij")
        dd = np.hypot(zm.x0 + I * zm.dx - qx, zm.y0 + J * zm.dy - qy)
        z = np.where(dd <= R, zm.z[I, J], np.nan)
        if np.isfinite(z).any():
            best = max(best, np.nanmax(z - np.nan_to_num(_env(c, np.minimum(dd, R)), nan=np.inf)))
        out[k] = best if np.isfinite(best) else np.nan
    return out


def brute_heights(hf, c, x, y, h=0.02, fine=0.002, around=0.04):
    """Independent CL over any ``heights(x, y)`` (a STEP part's exact heights): the design on
    an ``h`` lattice over the disk, then on a ``fine`` lattice within ``around`` of the best
    point; NaN where no design lies under the cutter."""
    R = c.radius
    g = np.arange(-R, R + h / 2, h)
    f = np.arange(-around, around + fine / 2, fine)
    out = np.full(len(x), np.nan)
    for k, (qx, qy) in enumerate(zip(x, y)):
        best, at = -np.inf, None
        for grid, centre in ((g, (qx, qy)), (f, None)):
            if centre is None:
                if at is None:
                    break
                centre = at
            cx, cy = centre
            U, V = np.meshgrid(cx + grid, cy + grid, indexing="ij")
            d = np.hypot(U - qx, V - qy)
            m = d <= R
            cl = np.asarray(hf(U[m], V[m]), dtype=float) - _env(c, d[m])
            if np.isfinite(cl).any() and np.nanmax(cl) > best:
                i = int(np.nanargmax(cl))
                best, at = float(cl[i]), (U[m][i], V[m][i])
        out[k] = best if np.isfinite(best) else np.nan
    return out
