"""EZ-map: extra height samples on the grid edges of a base z-map (paper 004, §3.2).

Procedure Construct_EZmap: every grid edge of the base that is steep (slope >= eps_r) or is
crossed by a sharp-edge (SE) curve gets e-map points, evenly spaced at no more than
``interval`` (default the tolerance), whose heights come from the exact surface. They are
stored compactly: CSR over the selected edges, each height a 16-bit code over its edge's
range (2 bytes per e-point, as in the paper's Table 2; the quantisation error is at most
1/131068 of the edge's range, 1.1e-4 mm for a 15 mm wall, see
:attr:`EZMap.resolution`). A single e-point more
than ``tol`` below both neighbours is lifted to the higher one and counted
(:attr:`EZMap.lifted`): it is a sample on a wall's line answered with a lower face.

Evaluation. A cell with e-points on any of its edges is a Coons patch (bilinearly blended,
transfinite) of its four boundary sequences: grid corners + e-points, linear between
samples; an edge without e-points is the base's cubic Bezier along it, so the patch meets
the base cells continuously. Where a boundary sequence is not G1 the break is located on
it: a jump (a vertical wall) mid-way between the two samples it falls between, so within
half the e-map interval, or a kink (a sharp edge) where the lines through the samples on
either side meet. A cell whose boundary holds two jumps (or, without jumps, two kinks) is
split along the trace joining them, and each side is evaluated from the boundary data on
its side only: the line through the point parallel to the trace's chord meets the cell
boundary at two points whose side heights are blended linearly (exact for planes and for
any surface that varies only across the trace, as walls, fillets along them and ridges
do). The trace is the circle arc through the two crossings whose sagitta is that of the
circles through them and the crossing found one lever (half a grid interval or more) out
along the trace on either side; where both neighbouring traces are straight and turn by
more than 30 degrees inside the cell it is the polyline through their meeting point (a
wall corner). A wall's position is so held to the e-map interval.

Cells whose base stencil reaches an e-edge answer too (:meth:`EZMap.cell_mask`): their
plain edges take the slope on the side away from a break, so that no cell of the model
blends heights across a wall or a sharp edge. Cells with breaks but no single trace (a
wall crossing one edge twice, two walls in one cell) fall back to the Coons patch kept
within the range of its boundary curves.

Beyond the paper (``build_ez(prune=True, verify=True)``, the defaults): candidate edges
whose e-points all lie within ``PRUNE_SHARE * tol`` of the base's Bezier curve are dropped
(on free-form parts most steep edges are smooth slopes the base already holds: cornetta
keeps 8,518 of 70,062), and every refined cell is checked against the exact surface at a
lattice of test points; a cell that misses (two walls or a rib inside it, a wall crossing
an edge twice, a wall corner) gets a finer e-map of its own or, last, a dense lattice
whose diagonal is the tolerance (:mod:`zmap.refine.patch`).

Grid edges and ids (the contract shared with :mod:`zmap.model`): the x-edge
``(i, j)-(i+1, j)`` has id ``i*ny + j``, the y-edge ``(i, j)-(i, j+1)`` has id
``(nx-1)*ny + i*(ny-1) + j``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from .. import features
from ..errors import RefineError
from ..grid import ZMap
from ._eedges import _n_points, split_forced
from ._emap import (  # noqa: F401  (BREAK_RATIO, FORMAT_VERSION, SERIAL_BELOW: importable here as before)
    BREAK_RATIO,
    FORMAT_VERSION,
    NAN_CODE,
    QUANTUM_SHARE,
    SERIAL_BELOW,
    EZMap,
    cells_around,
    decimate,
    edge_count,
    encode_heights,
)
from .patch import patch_failing

__all__ = ["NAN_CODE", "QUANTUM_SHARE", "EZMap", "build_ez", "decimate", "edge_count", "encode_heights"]

#: An edge whose e-points all lie within this share of the tolerance of the base's Bezier
#: curve along it carries nothing the base misses, and is dropped (``build_ez(prune=True)``).
PRUNE_SHARE = 0.25
#: A smooth e-edge keeps every ``s``-th e-point, ``s`` as large as lets the kept points
#: interpolate all of them linearly within this share of the tolerance
#: (:func:`zmap.refine._emap.decimate`; ``build_ez(thin=True)``).
THIN_SHARE = 0.125


def build_ez(base: ZMap, heights: Callable[[np.ndarray, np.ndarray], np.ndarray], *, tol: float,
             eps_r: float | None = None, se_curves: Sequence[np.ndarray] = (), interval: float | None = None,
             prune: bool = True, verify: bool = True, thin: bool = True) -> EZMap:
    """Procedure Construct_EZmap: e-points on the steep and SE-crossed edges of ``base``.

    Beyond the paper, two steps that a real die needs (both on by default):

    - ``prune``: a candidate edge whose e-points all lie within ``PRUNE_SHARE * tol`` of the
      base's cubic Bezier curve along it is dropped (a steep but smooth slope the base
      already holds; on free-form parts most steep edges are such);
    - ``thin``: an edge (or a cell patch's sub-edge) without a wall or a sharp edge keeps
      only every ``s``-th e-point, ``s`` as large as lets the kept points interpolate all
      of them linearly within ``THIN_SHARE * tol`` (a smooth steep slope needs a few
      samples, not one per ``interval``); a wall edge of the e-map keeps its samples
      around the jump and is thinned so either side of them (a window,
      :func:`zmap.refine._emap.decimate`); the check below then tests the thinned model;
    - ``verify``: every refined cell, and every cell next to a candidate edge, is checked
      against ``heights`` at a lattice of test points (:func:`zmap.refine.patch.misfit`:
      off by more than ``tol`` vertically with no exact height within ``tol`` around it to
      explain it); a cell that misses gets a finer e-map of its own
      (:mod:`zmap.refine.patch`), and cells still off after the finest level are counted in
      ``unresolved``.

    Parameters
    ----------
    base : ZMap
        Master z-map (its local frame is honoured).
    heights : callable
        ``heights(x, y) -> z``: exact top-most heights at world xy (two float64 arrays of
        shape (P,)), NaN where there is no surface; called once with every e-point.
    tol : float
        Tolerance in mm, smaller than the grid interval ``min(dx, dy)``.
    eps_r : float, optional
        Slope threshold of a steep edge; default :func:`zmap.features.default_eps_r`.
    se_curves : sequence of ndarray of shape (n, 2)
        Sharp-edge curves, world xy (:func:`zmap.features.sharp_edge_curves`).
    interval : float, optional
        Largest spacing of e-points along an edge, mm; default ``tol``.
    prune, verify, thin : bool
        Drop the edges the base holds; check the refined cells and patch the misses; thin
        the e-points of smooth edges.

    Returns
    -------
    EZMap
        ``failed`` counts the e-points whose height came back NaN, ``lifted`` the single
        e-points more than ``tol`` below both neighbours, lifted to the higher one (a
        sample on a wall's line answered with a lower face), ``pruned`` the candidate
        edges dropped, ``patches`` and ``unresolved`` what the check found.

    Raises
    ------
    ValueError
        ``tol`` or ``interval`` not smaller than the grid interval, or not positive.
    RefineError
        ``heights`` missing or returning the wrong shape.

    Examples
    --------
    >>> import numpy as np
    >>> from zmap import ZMap
    >>> f = lambda x, y: np.where(np.hypot(x - 2, y - 2) < 1.1, 3.0, 0.0)
    >>> base = ZMap.from_function(f, (0, 0, 4, 4), 0.5)
    >>> ez = build_ez(base, f, tol=0.01)
    >>> ez.n_edges > 0, ez.failed, ez.unresolved
    (True, 0, 0)
    """
    if not isinstance(base, ZMap):
        raise TypeError(f"base must be a zmap.ZMap, got {type(base).__name__}")
    if heights is None or not callable(heights):
        raise RefineError(f"the EZ-map needs the exact surface: heights must be a callable heights(x, y) -> z, "
                          f"got {type(heights).__name__}")
    h_min = min(base.dx, base.dy)
    tol = float(tol)
    if not (math.isfinite(tol) and tol > 0.0):
        raise ValueError(f"tol must be a positive length in mm, got {tol!r}")
    if tol >= h_min:
        raise ValueError(f"tol={tol!r} must be smaller than the grid interval min(dx, dy)={h_min!r}")
    interval = tol if interval is None else float(interval)
    if not (math.isfinite(interval) and 0.0 < interval < h_min):
        raise ValueError(f"interval={interval!r} must be positive and smaller than the grid interval "
                         f"min(dx, dy)={h_min!r}")
    eps_r = features.default_eps_r(tol, base.dx, base.dy) if eps_r is None else float(eps_r)
    if not (eps_r >= 0.0):
        raise ValueError(f"eps_r must be a slope >= 0, got {eps_r!r}")

    sx, sy = features.steep_edges(base, eps_r) if math.isfinite(eps_r) else (
        np.zeros((base.nx - 1, base.ny), bool), np.zeros((base.nx, base.ny - 1), bool))
    cx, cy = features.edges_crossing(base, se_curves) if len(se_curves) else (np.zeros_like(sx), np.zeros_like(sy))
    sx |= cx
    sy |= cy
    # an edge with no height at either end has nothing to refine
    zf = ~np.isnan(base.z)
    sx &= zf[:-1, :] | zf[1:, :]
    sy &= zf[:, :-1] | zf[:, 1:]
    nx, ny = base.shape
    edge_ids = np.concatenate([np.flatnonzero(sx.ravel()), (nx - 1) * ny + np.flatnonzero(sy.ravel())]).astype(np.int64)
    se_ids = np.concatenate([np.flatnonzero(cx.ravel()), (nx - 1) * ny + np.flatnonzero(cy.ravel())]).astype(np.int64)
    n_candidates = edge_ids.shape[0]
    if prune and edge_ids.size:
        # a steep edge (no sharp edge across it) is probed at a few points first: where the
        # base's Bezier holds them it is a smooth slope, and its e-points are not sampled
        # (on free-form sheets nearly every edge is above eps_r: bm2 at grid 2, 109 M e-points)
        probe = ~np.isin(edge_ids, se_ids)
        keep = np.ones(edge_ids.shape, dtype=bool)
        keep[probe] = _edges_off_base_at_probes(base, heights, edge_ids[probe], PRUNE_SHARE * tol)
        edge_ids = edge_ids[keep]
    n_x, n_y = _n_points(base.dx, interval), _n_points(base.dy, interval)
    counts = np.where(edge_ids < (nx - 1) * ny, n_x, n_y)
    offsets = np.zeros(edge_ids.shape[0] + 1, dtype=np.int64)
    np.cumsum(counts, out=offsets[1:])
    P = int(offsets[-1])
    ez = EZMap(base.x0, base.y0, base.dx, base.dy, nx, ny, interval, tol, edge_ids, offsets,
               np.zeros(P, dtype=np.uint16), np.zeros(edge_ids.shape[0], np.float32), np.zeros(edge_ids.shape[0], np.float32))
    if ez.n_points:
        lx, ly = ez.points()
        wx, wy = base.local_to_world(lx, ly)
        z = _call_heights(heights, wx, wy)
        ez.failed = int(np.count_nonzero(np.isnan(z)))
        from . import _ez_kernels as _k

        lifted = np.zeros(ez.n_edges, dtype=np.int64)
        z = np.ascontiguousarray(z)
        _k.despike(base.z, ez.edge_ids, ez.offsets, z, tol, lifted)
        if prune:
            keep = _edges_off_base(base, ez.offsets, wx, wy, z, PRUNE_SHARE * tol)
            point_keep = np.repeat(keep, np.diff(offsets))
            edge_ids, z, lifted = edge_ids[keep], z[point_keep], lifted[keep]
            offsets = np.zeros(edge_ids.shape[0] + 1, dtype=np.int64)
            np.cumsum(np.diff(ez.offsets)[keep], out=offsets[1:])
            ez.edge_ids, ez.offsets = edge_ids, offsets
            ez.win, ez.forced = np.full(edge_ids.shape[0], -1, np.int64), np.zeros(edge_ids.shape[0], np.int8)
        if thin:
            offsets, z, win = decimate(base.z, base.dx, base.dy, interval, tol, ez.edge_ids, ez.offsets, z,
                                       THIN_SHARE * tol, window=True)
            ez.offsets, (ez.win, ez.forced) = offsets, split_forced(win)
        ez.lifted = int(lifted.sum())
        ez.codes, ez.lo, ez.step = encode_heights(offsets, z, QUANTUM_SHARE * tol)
    ez.pruned = int(n_candidates - ez.n_edges)
    if verify and n_candidates:
        # the refined cells, and the cells a sharp edge crosses (a rib between the probes)
        cells = np.flatnonzero((cells_around(nx, ny, se_ids) | ez.cell_mask()).ravel()).astype(np.int64)

        def install(p):
            ez.patches = p if p.n_patches else None
            ez._cache = {}

        a = ez._tables(base) if ez.n_edges else None
        broken = a["ecell_ids"][a["nb"] > 0] if a is not None else None
        model = lambda x, y: ez.height(base, x, y)  # noqa: E731
        _patches, still = patch_failing(model, base, heights, tol, interval, cells, install, fine_cells=broken,
                                        thin=THIN_SHARE * tol if thin else None,
                                        bubbles=lambda bad: _bubbles(ez, base, heights, tol, bad, model))
        ez.unresolved = int(still.size)
    return ez


def _bubbles(ez: EZMap, base: ZMap, heights: Callable, tol: float, bad: np.ndarray, model: Callable) -> np.ndarray:
    """Give the Coons cells among ``bad`` a bubble (their exact centre height less the
    patch's, in whole quanta) and keep it where the cell then holds on the fine test
    lattice (as a patch is tested); returns the cells of ``bad`` still missing."""
    from .patch import CHECK_SHARE, TEST_POINTS, failing_cells

    cells = ez.coons_cells(base, bad)
    if cells.size == 0:
        return bad
    ci, cj = np.divmod(cells, base.ny - 1)
    wx, wy = base.local_to_world(base.x0 + (ci + 0.5) * base.dx, base.y0 + (cj + 0.5) * base.dy)
    r = np.asarray(heights(wx, wy), dtype=np.float64) - np.asarray(model(wx, wy), dtype=np.float64)
    q = QUANTUM_SHARE * tol
    with np.errstate(invalid="ignore"):
        k = np.where(np.isfinite(r), np.rint(r / q), 0.0)
    on = k != 0
    if not on.any():
        return bad
    ez.bub_cells, ez.bub_h = cells[on], k[on] * q
    ez._cache = {}
    still = failing_cells(model, base, heights, CHECK_SHARE * tol, ez.bub_cells, 4 * TEST_POINTS)
    keep = ~np.isin(ez.bub_cells, still)
    ez.bub_cells, ez.bub_h = ez.bub_cells[keep], ez.bub_h[keep]
    ez._cache = {}
    return np.setdiff1d(bad, ez.bub_cells)


#: probe points per steep edge, at t = q / (PROBES + 1)
PROBES = 7


def _edges_off_base_at_probes(base: ZMap, heights: Callable, edge_ids: np.ndarray, limit: float) -> np.ndarray:
    """Which ``edge_ids`` have a probe point more than ``limit`` off the base's Bezier."""
    from . import _ez_kernels as _k

    if edge_ids.size == 0:
        return np.zeros(0, dtype=bool)
    nx, ny = base.shape
    offsets = np.arange(edge_ids.shape[0] + 1, dtype=np.int64) * PROBES
    lx = np.empty(int(offsets[-1]))
    ly = np.empty(int(offsets[-1]))
    _k.edge_points(edge_ids, offsets, base.x0, base.y0, base.dx, base.dy, nx, ny, lx, ly)
    wx, wy = base.local_to_world(lx, ly)
    return _edges_off_base(base, offsets, wx, wy, _call_heights(heights, wx, wy), limit)


def _call_heights(heights: Callable, wx: np.ndarray, wy: np.ndarray) -> np.ndarray:
    """``heights(wx, wy)`` as float64, checked for one height per point."""
    z = np.asarray(heights(wx, wy), dtype=np.float64)
    if z.shape != wx.shape:
        raise RefineError(f"heights(x, y) must return one height per point, shape {wx.shape}, got {z.shape}")
    return z


def _edges_off_base(base: ZMap, offsets: np.ndarray, wx: np.ndarray, wy: np.ndarray, z: np.ndarray,
                    limit: float) -> np.ndarray:
    """Edges with an e-point more than ``limit`` off the base's Bezier (or a surface where it has none)."""
    from ..interpolate import bezier

    zb = np.asarray(bezier(base, wx, wy), dtype=np.float64)
    with np.errstate(invalid="ignore"):
        off = ~(np.abs(z - zb) <= limit) & ~(np.isnan(z) & np.isnan(zb))
    E = offsets.shape[0] - 1
    keep = np.zeros(E, dtype=bool)
    keep[np.repeat(np.arange(E), np.diff(offsets))[off]] = True
    return keep
