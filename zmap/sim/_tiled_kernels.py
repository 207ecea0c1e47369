"""Numba kernels behind :mod:`zmap.sim.tiled`: which tiles a position reaches, and cutting a tile.

A tile is cut by the whole-stock loop itself (``_dexel_kernels.cut_pieces_window``) over
the stages whose pieces reach it, on the rays ``gi0 <= i < gi0 + tnx``, ``gj0 <= j < gj0 + tny``:
each ray's xy comes from its global index exactly as in the whole-stock run
(``x0 + i*pitch``), and each position keeps its global stage, so each tile's dexels and
history events are the single-process run's, ray for ray.
"""

from __future__ import annotations


from numba import njit

from ._dexel_kernels import cut_pieces_window, piece_window
from ._sweep_kernels import NO_CUT

__all__ = ["cut_pieces_tile", "positions_reaching"]


@njit(cache=True)
def positions_reaching(pkind, pgeo, smove, st0, st1, tslot, trad, x0, y0, pitch, nx, ny, tile, nty, counts,
                       out_tile, fill):
    """Tiles (``tile`` x ``tile`` rays, ``nty`` along y) that each stage's piece window reaches.

    The window is the whole-stock kernel's (:func:`zmap.sim._dexel_kernels.piece_window`,
    clipped to the stock). ``fill`` False: count per stage into ``counts``; True: write the
    tile ids from ``counts[p]`` on into ``out_tile``.
    """
    for p in range(smove.shape[0]):
        n = 0
        if pkind[smove[p]] != NO_CUT:
            i0, i1, j0, j1 = piece_window(pkind, pgeo, smove[p], st0[p], st1[p], trad[tslot[p]], x0, y0, pitch,
                                          0, 0, nx, ny)
            if i0 <= i1 and j0 <= j1:
                for a in range(i0 // tile, i1 // tile + 1):
                    for b in range(j0 // tile, j1 // tile + 1):
                        if fill:
                            out_tile[counts[p] + n] = a * nty + b
                        n += 1
        if not fill:
            counts[p] = n


#: cut a tile's stages into its rays: the whole-stock loop over a window of rays
cut_pieces_tile = cut_pieces_window
