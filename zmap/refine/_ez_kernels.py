"""Numba kernels behind :mod:`zmap.refine.ez`: the evaluation drivers :func:`ez_kernel` and
:func:`patch_kernel`, and under this path (callers read them as ``_k.<name>``) those of the
modules they live in, one per job. No validation here: callers own the API.

- :mod:`zmap.refine._edge_kernels`: an edge's samples read from its codes, windows, breaks;
- :mod:`zmap.refine._thin_kernels`: e-point places, despiking, thinning and windowing;
- :mod:`zmap.refine._coons_kernels`: a cell's boundary curves and their Coons patch;
- :mod:`zmap.refine._trace_kernels`: the trace that splits a cell with two breaks;
- :mod:`zmap.refine._split_kernels`: the height on either side of that trace.

Conventions (see :class:`zmap.refine.ez.EZMap`):

- edge ids: x-edge ``(i, j)-(i+1, j)`` is ``i*ny + j``; y-edge ``(i, j)-(i, j+1)`` is
  ``(nx-1)*ny + i*(ny-1) + j``. Edge ``k`` of the e-map carries ``n = offsets[k+1] -
  offsets[k]`` interior samples at ``t = q/(n+1)``, ``q = 1..n``; with the two grid corners
  (``q = 0`` and ``q = n+1``) they form the edge's boundary sequence. The evaluation
  kernels take the *virtual* offsets (a windowed wall edge counts its full samples) and
  read samples through :func:`_sample`, whose ``hq = (codes, lo, step, cstart, win)``
  knows where each edge's codes start and how a windowed edge stores them.
- a cell ``(i, j)`` has id ``i*(ny-1) + j`` and local edges 0 bottom (+x), 1 right (+y),
  2 top (+x), 3 left (+y); its perimeter coordinate ``s`` runs counter-clockwise from the
  corner ``(i, j)``: bottom ``s = t``, right ``1 + t``, top ``2 + (1 - t)``, left
  ``3 + (1 - t)``. Cell-local coordinates are metric: ``(u*dx, v*dy)``.
- a break on an edge is a jump (kind 1, a vertical wall) or a kink (kind 2, a sharp edge)
  of its boundary sequence, at parameter ``brk_t``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .._interp_kernels import _locate
from ._coons_kernels import (  # noqa: F401
    _coons,
    _edge_nodes,
    _edge_value,
    _find,
    coons_blend,
    plain_edge_slopes,
)
from ._edge_kernels import (
    BREAK_JUMP,
    BREAK_KINK,
    BREAK_NONE,
    NAN_CODE,
    WIN_FORCED,
    WIN_KINK,
    WINDOW_HALF,
    detect_breaks,
    pack_window,
    unpack_window,
    window_break,
    window_size,
)
from ._split_kernels import _split
from ._thin_kernels import (
    decimate_counts,
    despike,
    edge_points,
    resample,
    window_counts,
    window_resample,
)
from ._trace_kernels import CORNER_TURN, MAX_WALK, MIN_LEVER, cell_geometry

__all__ = ["BREAK_JUMP", "BREAK_KINK", "BREAK_NONE", "CORNER_TURN", "MAX_WALK", "MIN_LEVER", "NAN_CODE",
           "WINDOW_HALF", "WIN_FORCED", "WIN_KINK", "cell_geometry", "coons_blend", "decimate_counts", "despike",
           "detect_breaks", "edge_points", "ez_kernel", "ez_kernel_serial", "pack_window", "patch_kernel",
           "patch_kernel_serial", "plain_edge_slopes", "resample", "unpack_window", "window_break",
           "window_counts", "window_resample", "window_size"]


@njit(cache=True, error_model="numpy", parallel=True)
def ez_kernel(z, x0, y0, dx, dy, cs, sn, ox, oy, xs, ys, edge_ids, offsets, hq, brk_kind, brk_t,
              ecell_ids, slots, nb, bk, bt, pts, arc, bub, out):
    """EZ hq at every query point; NaN outside e-cells (the caller uses the base); ``bub``:
    each e-cell's bubble height (:func:`_coons`)."""
    nx, ny = z.shape
    for p in prange(xs.shape[0]):
        i, j, u, v = _locate(xs[p], ys[p], x0, y0, dx, dy, cs, sn, ox, oy, nx, ny)
        if i < 0:
            out[p] = np.nan
            continue
        c = _find(ecell_ids, i * (ny - 1) + j)
        if c < 0 or math.isnan(z[i, j]) or math.isnan(z[i + 1, j]) or math.isnan(z[i, j + 1]) or math.isnan(z[i + 1, j + 1]):
            out[p] = np.nan
            continue
        if nb[c] == 2 and (pts[c, 0, 0] != pts[c, 2, 0] or pts[c, 0, 1] != pts[c, 2, 1]):
            out[p] = _split(z, i, j, u, v, c, slots, edge_ids, offsets, hq, brk_kind, brk_t, bk, bt, pts, arc, dx, dy)
        else:
            out[p] = _coons(z, i, j, u, v, c, slots, edge_ids, offsets, hq, brk_kind, brk_t, dx, dy, nb[c] > 0, bub[c])


#: :func:`ez_kernel` on one thread: for small batches (a cell patch's few points), where
#: waking the thread pool costs more than the points themselves
ez_kernel_serial = njit(cache=True, error_model="numpy")(ez_kernel.py_func)


@njit(cache=True, error_model="numpy", parallel=True)
def patch_kernel(zs, x0s, y0s, dx, dy, cs, sn, ox, oy, xs, ys, ks, edge_ids, offsets, codes, lo, step, brk_kind,
                 brk_t, ecell_ids, slots, nb, bk, bt, pts, arc, nowin, out):
    """:func:`ez_kernel` over a stack of same-level cell patches: point ``p`` lies in patch
    ``ks[p]``, whose sub-grid is ``zs[k]`` at ``(x0s[k], y0s[k])`` and whose per-edge and
    per-cell tables are row ``k`` of the stacked arrays (ids and slots are shared: every
    patch of a level has every sub-edge; ``offsets[k]`` are patch k's, its sub-edges thinned
    to their own counts; ``nowin``: -1 per sub-edge, patches store no windows)."""
    for p in prange(xs.shape[0]):
        k = ks[p]
        z = zs[k]
        nx, ny = z.shape
        i, j, u, v = _locate(xs[p], ys[p], x0s[k], y0s[k], dx, dy, cs, sn, ox, oy, nx, ny)
        if i < 0:
            out[p] = np.nan
            continue
        c = _find(ecell_ids, i * (ny - 1) + j)
        if c < 0 or math.isnan(z[i, j]) or math.isnan(z[i + 1, j]) or math.isnan(z[i, j + 1]) or math.isnan(z[i + 1, j + 1]):
            out[p] = np.nan
            continue
        off = offsets[k]
        hq = (codes[k], lo[k], step[k], off[:-1], nowin)
        if nb[k, c] == 2 and (pts[k, c, 0, 0] != pts[k, c, 2, 0] or pts[k, c, 0, 1] != pts[k, c, 2, 1]):
            out[p] = _split(z, i, j, u, v, c, slots, edge_ids, off, hq, brk_kind[k], brk_t[k], bk[k], bt[k], pts[k],
                            arc[k], dx, dy)
        else:
            out[p] = _coons(z, i, j, u, v, c, slots, edge_ids, off, hq, brk_kind[k], brk_t[k], dx, dy, nb[k, c] > 0,
                            0.0)


#: :func:`patch_kernel` on one thread, for small batches
patch_kernel_serial = njit(cache=True, error_model="numpy")(patch_kernel.py_func)
