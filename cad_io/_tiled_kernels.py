"""Numba kernels behind :mod:`cad_io.tiled`: the grid sampler's pair scan on one tile.

The same scan as ``_sample_kernels.count_pairs``/``fill_pairs`` (same triangle window, same
barycentric limits, same order: triangle by triangle, then i, then j), on the whole map's
grid ``x0 + i*dx, y0 + j*dy`` but only for the nodes of the tile ``ti0 <= i < ti1``,
``tj0 <= j < tj1``. A pair's grid index is local to the tile (``(i - ti0) * (tj1 - tj0) +
(j - tj0)``), and the solver reads the node's coordinates from arrays computed as the
whole-map kernel computes them, so each tile's heights are the in-memory map's to the
last bit.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ._sample_kernels import _bary_limits, _tri_xy, _widened_window

__all__ = ["count_pairs_tile", "fill_pairs_tile"]


@njit(cache=True, error_model="numpy")
def _scan_tile_tri(nodes, tris, tri_margin, t, x0, y0, dx, dy, nx, ny, ti0, ti1, tj0, tj1, p, gidx, tri, w,
                   fill):
    ax, ay, bx, by, cx, cy, area = _tri_xy(nodes, tris, t)
    if area == 0.0:
        return 0
    inv = 1.0 / area
    mg = tri_margin[t]
    l0, l1, l2_ = _bary_limits(ax, ay, bx, by, cx, cy, area, mg)
    i0, i1, j0, j1 = _widened_window(ax, ay, bx, by, cx, cy, x0, y0, dx, dy, nx, ny, l0, l1, l2_)
    i0 = max(i0, ti0)
    i1 = min(i1, ti1 - 1)
    j0 = max(j0, tj0)
    j1 = min(j1, tj1 - 1)
    tny = tj1 - tj0
    n = 0
    for i in range(i0, i1 + 1):
        px = x0 + i * dx
        for j in range(j0, j1 + 1):
            py = y0 + j * dy
            w1 = ((px - ax) * (cy - ay) - (cx - ax) * (py - ay)) * inv
            w2 = ((bx - ax) * (py - ay) - (px - ax) * (by - ay)) * inv
            if w1 >= l1 and w2 >= l2_ and 1.0 - w1 - w2 >= l0:
                if fill:
                    gidx[p + n] = (i - ti0) * tny + (j - tj0)
                    tri[p + n] = t
                    w[p + n, 0] = w1
                    w[p + n, 1] = w2
                n += 1
    return n


@njit(cache=True, error_model="numpy", parallel=True)
def count_pairs_tile(nodes, tris, tri_margin, x0, y0, dx, dy, nx, ny, ti0, ti1, tj0, tj1, counts):
    """Pairs (tile node, triangle) per triangle into ``counts`` (M,)."""
    no_i = np.empty(0, dtype=np.int64)
    no_w = np.empty((0, 2))
    for t in prange(tris.shape[0]):
        counts[t] = _scan_tile_tri(nodes, tris, tri_margin, t, x0, y0, dx, dy, nx, ny, ti0, ti1, tj0, tj1, 0,
                                   no_i, no_i, no_w, False)


@njit(cache=True, error_model="numpy", parallel=True)
def fill_pairs_tile(nodes, tris, tri_margin, t0, offsets, x0, y0, dx, dy, nx, ny, ti0, ti1, tj0, tj1, gidx, tri,
                    w):
    """Pairs of triangles ``t0 .. t0 + len(offsets) - 2`` from ``offsets[tt]`` on."""
    for tt in prange(offsets.shape[0] - 1):
        if offsets[tt + 1] == offsets[tt]:
            continue
        _scan_tile_tri(nodes, tris, tri_margin, t0 + tt, x0, y0, dx, dy, nx, ny, ti0, ti1, tj0, tj1, offsets[tt],
                       gidx, tri, w, True)
