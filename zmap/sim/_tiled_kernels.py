"""Numba kernel behind :mod:`zmap.sim.tiled`: cutting the positions that reach one tile of rays.

The same loop as ``_dexel_kernels.cut_positions`` over a chosen list of positions, on the
rays ``gi0 <= i < gi0 + tnx``, ``gj0 <= j < gj0 + tny`` of the whole stock. Each ray's xy is
computed from its global index exactly as the whole-stock kernel computes it
(``x0 + i*pitch``), and each position keeps its global stage (``stage0 + p + 1``), so each
tile's dexels and history events are the single-process run's, ray for ray. Rays are
numbered locally in the tile's arrays (``(i - gi0) * tny + (j - gj0)``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ._dexel_kernels import (NEED_POOL, NEED_SLOTS, OK, ST_RAYS_CUT, ST_STATUS, ST_TR_N, ST_TT_N, ST_ZT_N,
                             cut_ray)
from ._tool_kernels import _envelope

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


@njit(cache=True)
def cut_positions_tile(xyz, tslot, tcode, trad, tcr, tlen, gpos, start, stop, stage0,
                       x0, y0, pitch, gi0, gj0, tnx, tny, near, far, cnt,
                       rec_z, zid_near, zid_far, zt_z, zt_c, zt_d, zt_ray,
                       rec_t, tt_z, tt_s, tt_ray,
                       rec_tr, leaf, tr_z, tr_s, tr_k, tr_ray, stats):
    """Cut positions ``start..stop-1`` of the tile's list into the tile.

    ``xyz``, ``tslot`` hold only the positions that reach the tile, in program order;
    ``gpos[q]`` is position q's index in the whole program, and it makes stage
    ``stage0 + gpos[q] + 1``. Returns the first position not (fully) cut: ``stop`` when
    done, else where to resume after growing what ``stats[ST_STATUS]`` names.
    """
    K = near.shape[1]
    zt_cap = zt_z.shape[0]
    tt_cap = tt_z.shape[0]
    tr_cap = tr_z.shape[0]
    stats[ST_STATUS] = OK
    for p in range(start, stop):
        s = tslot[p]
        code = tcode[s]
        R = trad[s]
        rc = tcr[s]
        L = tlen[s]
        tx = xyz[p, 0]
        ty = xyz[p, 1]
        tz = xyz[p, 2]
        stage = np.int32(stage0 + gpos[p] + 1)
        i0 = int(math.ceil((tx - R - x0) / pitch)) - 1
        i1 = int(math.floor((tx + R - x0) / pitch)) + 1
        j0 = int(math.ceil((ty - R - y0) / pitch)) - 1
        j1 = int(math.floor((ty + R - y0) / pitch)) + 1
        if i0 < gi0:
            i0 = gi0
        if j0 < gj0:
            j0 = gj0
        if i1 > gi0 + tnx - 1:
            i1 = gi0 + tnx - 1
        if j1 > gj0 + tny - 1:
            j1 = gj0 + tny - 1
        b = np.float32(tz + L)
        R2 = R * R
        for i in range(i0, i1 + 1):
            dxr = x0 + i * pitch - tx
            for j in range(j0, j1 + 1):
                dyr = y0 + j * pitch - ty
                d2 = dxr * dxr + dyr * dyr
                if d2 > R2:
                    continue
                r = (i - gi0) * tny + (j - gj0)
                c = cnt[r]
                if c == 0:
                    continue
                a = np.float32(tz + _envelope(code, R, rc, math.sqrt(d2)))
                if far[r, c - 1] <= a or near[r, 0] >= b:
                    continue
                if c >= K:
                    stats[ST_STATUS] = NEED_SLOTS
                    return p
                if (rec_z and stats[ST_ZT_N] + 2 > zt_cap) or (rec_t and stats[ST_TT_N] + 1 > tt_cap) \
                        or (rec_tr and stats[ST_TR_N] + 2 > tr_cap):
                    stats[ST_STATUS] = NEED_POOL
                    return p
                stats[ST_RAYS_CUT] += 1
                cut_ray(r, a, b, stage, near, far, cnt,
                        rec_z, zid_near, zid_far, zt_z, zt_c, zt_d, zt_ray,
                        rec_t, tt_z, tt_s, tt_ray,
                        rec_tr, leaf, tr_z, tr_s, tr_k, tr_ray, stats)
    return stop
