"""Numba kernels behind :mod:`zmap.sim.tiled`: which tiles a position reaches, and cutting a tile.

A tile is cut by the whole-stock loop itself (``_dexel_kernels.cut_positions_window``) over
the positions that reach it, on the rays ``gi0 <= i < gi0 + tnx``, ``gj0 <= j < gj0 + tny``:
each ray's xy comes from its global index exactly as in the whole-stock run
(``x0 + i*pitch``), and each position keeps its global stage, so each tile's dexels and
history events are the single-process run's, ray for ray.
"""

from __future__ import annotations

import math

from numba import njit

from ._dexel_kernels import cut_positions_window

__all__ = ["cut_positions_tile", "positions_reaching"]


@njit(cache=True)
def positions_reaching(xyz, tslot, trad, x0, y0, pitch, nx, ny, tile, nty, counts, out_tile, fill):
    """Tiles (``tile`` x ``tile`` rays, ``nty`` along y) that each position's footprint window reaches.

    The window is the whole-stock kernel's (``ceil((tx - R - x0) / pitch) - 1`` ..
    ``floor((tx + R - x0) / pitch) + 1``, clipped to the stock). ``fill`` False: count per
    position into ``counts``; True: write the tile ids from ``counts[p]`` on into ``out_tile``.
    """
    for p in range(xyz.shape[0]):
        R = trad[tslot[p]]
        tx = xyz[p, 0]
        ty = xyz[p, 1]
        i0 = max(int(math.ceil((tx - R - x0) / pitch)) - 1, 0)
        i1 = min(int(math.floor((tx + R - x0) / pitch)) + 1, nx - 1)
        j0 = max(int(math.ceil((ty - R - y0) / pitch)) - 1, 0)
        j1 = min(int(math.floor((ty + R - y0) / pitch)) + 1, ny - 1)
        n = 0
        if i0 <= i1 and j0 <= j1:
            for a in range(i0 // tile, i1 // tile + 1):
                for b in range(j0 // tile, j1 // tile + 1):
                    if fill:
                        out_tile[counts[p] + n] = a * nty + b
                    n += 1
        if not fill:
            counts[p] = n


#: cut a tile's positions into its rays: the whole-stock loop over a window of rays
cut_positions_tile = cut_positions_window
