"""The e-map: :class:`EZMap`, evaluated and stored, and the evaluation of its :class:`CellPatches`.

An EZ-map holds e-points on grid edges of a base z-map as 16-bit codes and evaluates its
cells as Coons patches split along walls and sharp edges (paper 004 §3.2, see
:mod:`zmap.refine.ez`); the cells that missed the exact surface carry a finer EZ-map of
their own or a dense lattice (:class:`CellPatches`, see :mod:`zmap.refine.patch`). The two
types hold each other (an e-map stores its patches, an EZ patch is evaluated as an e-map over
its cell's sub-grid), so the patches' evaluation lives here and their data and storage below
(:class:`zmap.refine._patches.CellPatchData`); the codes and their storage are
:mod:`zmap.refine._ecodec`'s, the e-edges and their thinning :mod:`zmap.refine._eedges`'s.
The procedures that build them are :func:`zmap.refine.ez.build_ez` and
:func:`zmap.refine.patch.patch_failing`, which import this module (and ``ez`` imports
``patch``: no cycle). Public names are re-exported from ``zmap.refine.ez`` and
``zmap.refine.patch``, and this module's from the modules below it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..grid import ZMap
from ._ecodec import (
    NAN_CODE,
    QUANTUM_SHARE,
    _pack_steps,
    _unpack_bits,
    _unpack_steps,
    encode_heights,
    pack_bubbles,
    pack_codes,
    pack_edge_counts,
    pack_offsets,
    unpack_bubbles,
    unpack_codes,
    unpack_offsets,
)
from ._eedges import (
    BREAK_RATIO,
    WINDOW_HALF,
    _n_points,
    break_thresholds,
    cells_around,
    decimate,
    edge_count,
    pack_windows,
    split_forced,
    unpack_windows,
    virtual_offsets,
)
from ._patches import (
    CellPatchData,
    SubLattices,
    all_edges,
    code_patch,
    full_counts,
    sub_grid,
)

__all__ = ["BREAK_RATIO", "FORMAT_VERSION", "NAN_CODE", "QUANTUM_SHARE", "SERIAL_BELOW", "WINDOW_HALF", "CellPatches",
           "EZMap", "SubLattices", "all_edges", "break_thresholds", "cells_around", "code_patch", "decimate",
           "edge_count", "encode_heights", "full_counts", "pack_codes", "sub_grid", "unpack_codes"]

FORMAT_VERSION = 6
#: Batches smaller than this are evaluated on one thread (no thread-pool wake-up).
SERIAL_BELOW = 4096


@dataclass(eq=False)
class EZMap:
    """The e-map of a base z-map: samples on selected grid edges.

    Parameters
    ----------
    x0, y0, dx, dy : float
        Grid of the base (local frame of the base), mm.
    nx, ny : int
        Grid points of the base.
    interval : float
        Largest spacing of the e-points along an edge, mm.
    tol : float
        Tolerance the map was built for, mm (sets the break thresholds).
    edge_ids : ndarray of shape (E,), int64
        Sorted ids of the edges that carry e-points.
    offsets : ndarray of shape (E+1,), int64
        CSR offsets: edge ``edge_ids[k]`` owns points ``offsets[k]:offsets[k+1]``, the
        ``n_e`` interior points of the edge at ``t = (q+1)/(n_e+1)`` from its first grid
        point.
    codes : ndarray of shape (P,), uint16
        Heights as 16-bit codes (as the paper's Table 2 stores e-points, 2 bytes each):
        ``height = lo[k] + step[k] * code`` in mm; ``65535`` where the surface gave none.
    lo, step : ndarray of shape (E,), float32
        Per-edge offset and quantum of the codes, mm; the quantisation error is at most
        ``step / 2`` (:attr:`resolution`): 1/131068 of the edge's height range, 1.1e-4 mm
        for a 15 mm wall.
    failed : int
        E-points whose height came back NaN from the ``heights`` callable.
    lifted : int
        E-points lifted to their higher neighbour: a single sample more than ``tol`` below
        both neighbours is a point on a wall's line that the surface callable answered
        with a lower face (the top-most height there is the wall's top).
    patches : zmap.refine.patch.CellPatches, optional
        Finer e-maps over the cells that missed the exact surface when the map was checked
        (``build_ez(verify=True)``); each answers for its cell.
    unresolved : int
        Cells still off the exact surface at a test point after the finest patch level.
    pruned : int
        Candidate edges dropped because the base already held them (``build_ez(prune=True)``).
    forced : ndarray of shape (E,), int8, optional
        Forced break of each windowed edge (1 a jump, 2 a kink; 0, the default, searched
        for): the full sequence's, in the interval its window holds
        (:func:`zmap.refine._ez_kernels.detect_breaks`). A ``win`` given with the flag bits
        :data:`zmap.refine._ez_kernels.WIN_FORCED` / ``WIN_KINK`` (as :func:`decimate`
        returns it) sets it, and ``win`` is kept without them.
    win : ndarray of shape (E,), int64, optional
        Windowed wall edges (``build_ez(thin=True)``): ``win[k] >= 0`` packs the window of
        edge k (:func:`zmap.refine._ez_kernels.pack_window`), whose ``offsets`` count the
        codes it stores (knots either side of the full samples around its jump), not its
        full samples; -1 (the default, all edges) for an edge that stores its samples.
    bub_cells, bub_h : ndarray of shape (B,), optional
        Bubbles: cells (sorted flat ids, Coons cells of the map) whose Coons patch gets
        ``bub_h * 16 u (1 - u) v (1 - v)`` added, ``bub_h`` the exact height at the cell's
        centre less the patch's there, in mm (whole quanta of :data:`QUANTUM_SHARE` tol).
        Over a smooth surface the Coons patch of exact boundary curves errs by about that
        shape (its leading error term); ``build_ez(verify=True)`` gives a cell that misses a
        bubble before a cell patch, and keeps it where the cell then holds.

    Examples
    --------
    >>> import numpy as np
    >>> from zmap import ZMap
    >>> from zmap.refine.ez import build_ez
    >>> f = lambda x, y: np.where(x > 1.23, 5.0, 0.0)
    >>> base = ZMap.from_function(f, (0, 0, 3, 3), 0.5)
    >>> ez = build_ez(base, f, tol=0.01)
    >>> round(float(ez.evaluate(base, 1.225, 1.6)), 3), round(float(ez.evaluate(base, 1.235, 1.6)), 3)
    (0.0, 5.0)
    """

    x0: float
    y0: float
    dx: float
    dy: float
    nx: int
    ny: int
    interval: float
    tol: float
    edge_ids: np.ndarray
    offsets: np.ndarray
    codes: np.ndarray
    lo: np.ndarray
    step: np.ndarray
    failed: int = 0
    lifted: int = 0
    patches: Any = None
    unresolved: int = 0
    pruned: int = 0
    win: Any = None
    forced: Any = None
    bub_cells: Any = None
    bub_h: Any = None
    _cache: dict = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        self.x0, self.y0, self.dx, self.dy = (float(v) for v in (self.x0, self.y0, self.dx, self.dy))
        self.nx, self.ny, self.failed, self.lifted = int(self.nx), int(self.ny), int(self.failed), int(self.lifted)
        self.unresolved, self.pruned = int(self.unresolved), int(self.pruned)
        self.bub_cells = np.ascontiguousarray(np.zeros(0) if self.bub_cells is None else self.bub_cells, dtype=np.int64)
        self.bub_h = np.ascontiguousarray(np.zeros(0) if self.bub_h is None else self.bub_h, dtype=np.float64)
        if self.bub_h.shape != self.bub_cells.shape or self.bub_cells.ndim != 1 or (self.bub_cells.size and (
                np.any(np.diff(self.bub_cells) <= 0) or self.bub_cells[0] < 0
                or self.bub_cells[-1] >= (int(self.nx) - 1) * (int(self.ny) - 1))):
            raise ValueError("bubbles: increasing cells of the grid, one height each")
        if self.patches is not None and self.patches.n_patches and (
                self.patches.cells[0] < 0 or self.patches.cells[-1] >= (self.nx - 1) * (self.ny - 1)):
            raise ValueError("patched cells must be cells of the grid")
        self.interval, self.tol = float(self.interval), float(self.tol)
        if self.nx < 2 or self.ny < 2:
            raise ValueError(f"nx and ny must be >= 2, got nx={self.nx}, ny={self.ny}")
        self.edge_ids = np.ascontiguousarray(self.edge_ids, dtype=np.int64)
        self.offsets = np.ascontiguousarray(self.offsets, dtype=np.int64)
        self.codes = np.ascontiguousarray(self.codes, dtype=np.uint16)
        self.lo = np.ascontiguousarray(self.lo, dtype=np.float32)
        self.step = np.ascontiguousarray(self.step, dtype=np.float32)
        E = self.edge_ids.shape[0]
        if self.lo.shape != (E,) or self.step.shape != (E,):
            raise ValueError(f"lo and step must have shape (E,) = ({E},), got {self.lo.shape} and {self.step.shape}")
        if self.edge_ids.ndim != 1 or self.offsets.shape != (E + 1,):
            raise ValueError(f"offsets must have shape (E+1,) = ({E + 1},) for {E} edge ids, got {self.offsets.shape}")
        if E and (np.any(np.diff(self.edge_ids) <= 0) or self.edge_ids[0] < 0
                  or self.edge_ids[-1] >= edge_count(self.nx, self.ny)):
            raise ValueError("edge_ids must be strictly increasing ids of edges of the grid")
        if self.offsets[0] != 0 or np.any(np.diff(self.offsets) < 0) or self.offsets[-1] != self.codes.shape[0]:
            raise ValueError(f"offsets must rise from 0 to len(codes)={self.codes.shape[0]}, "
                             f"got {self.offsets[0]}..{self.offsets[-1] if E + 1 else None}")
        self.win = (np.full(E, -1, dtype=np.int64) if self.win is None
                    else np.ascontiguousarray(self.win, dtype=np.int64))
        if self.win.shape != (E,):
            raise ValueError(f"win must have shape (E,) = ({E},), got {self.win.shape}")
        from . import _ez_kernels as _k

        flag = (self.win >= 0) & ((self.win & _k.WIN_FORCED) != 0)
        self.win, flagged = split_forced(self.win)
        forced = flagged if self.forced is None else np.asarray(self.forced, dtype=np.int8).ravel()
        if forced.shape != (E,):
            raise ValueError(f"forced must have shape (E,) = ({E},), got {forced.shape}")
        self.forced = np.ascontiguousarray(np.where(flag, flagged, forced), dtype=np.int8)
        if np.any((self.forced < 0) | (self.forced > 2)) or np.any((self.forced != 0) & (self.win < 0)):
            raise ValueError(f"forced must hold 0, 1 or 2 per e-edge ({E}), non-zero only on windowed edges")
        w = np.flatnonzero(self.win >= 0)
        if w.size:
            full = self.full_counts()[w]
            a, c = self.win[w] & 0x7FFF, (self.win[w] >> 16) & 0x7FFF
            size = np.array([_k.window_size(int(v), int(f)) for v, f in zip(self.win[w], full)], dtype=np.int64)
            bad = (a >= c) | (c > full + 1) | (size != np.diff(self.offsets)[w])
            if bad.any():
                k = int(w[np.flatnonzero(bad)[0]])
                raise ValueError(f"e-edge {int(self.edge_ids[k])}: its window {self.window(k)} does not fit its "
                                 f"{int(full[np.flatnonzero(bad)[0]])} samples and {int(np.diff(self.offsets)[k])} codes")

    # ---- figures --------------------------------------------------------------------------

    def full_counts(self) -> np.ndarray:
        """Full samples of each e-edge, (E,) int64: what a windowed edge is read as (the
        e-map interval's count on an x- or y-edge), what the others store."""
        cnt = np.diff(self.offsets)
        if np.any(self.win >= 0):
            is_x = self.edge_ids < (self.nx - 1) * self.ny
            cnt = np.where(self.win >= 0, np.where(is_x, _n_points(self.dx, self.interval),
                                                   _n_points(self.dy, self.interval)), cnt)
        return cnt

    def window(self, k: int) -> tuple[int, int, int, int] | None:
        """``(a, c, dl, dr)`` of e-edge ``k``'s window (full samples ``a..c`` kept, ``dl``
        intervals over ``[0, a]``, ``dr`` over ``[c, n + 1]``), None if it has none."""
        w = int(self.win[k])
        return None if w < 0 else (w & 0x7FFF, (w >> 16) & 0x7FFF, (w >> 32) & 0xFFFF, (w >> 48) & 0xFFFF)

    def window_break(self, k: int) -> int:
        """Kind of e-edge ``k``'s forced break (1 a jump, 2 a kink), 0 where it has no window
        or its break is searched for (:func:`zmap.refine._ez_kernels.detect_breaks`)."""
        return int(self.forced[k])

    @property
    def n_windows(self) -> int:
        """Number of windowed wall edges."""
        return int(np.count_nonzero(self.win >= 0))

    def _voff(self) -> np.ndarray:
        """Offsets the kernels index by (:func:`virtual_offsets`), cached."""
        of = self._cache.get("voff_of")
        if of is None or of[0] is not self.offsets or of[1] is not self.win:
            self._cache["voff"] = virtual_offsets(self.offsets, self.full_counts(), self.win)
            self._cache["voff_of"] = (self.offsets, self.win)
        return self._cache["voff"]

    @classmethod
    def from_heights(cls, x0: float, y0: float, dx: float, dy: float, nx: int, ny: int, interval: float, tol: float,
                     edge_ids: np.ndarray, offsets: np.ndarray, heights: np.ndarray, **kwargs) -> EZMap:
        """The e-map of e-point ``heights`` (float, NaN = none; shape (P,)), coded to 16 bits."""
        codes, lo, step = encode_heights(np.asarray(offsets, dtype=np.int64), np.asarray(heights, dtype=np.float64))
        return cls(x0, y0, dx, dy, nx, ny, interval, tol, edge_ids, offsets, codes, lo, step, **kwargs)

    @property
    def heights(self) -> np.ndarray:
        """Decoded stored e-point heights, ndarray of shape (P,), float64, mm (NaN = none); a
        windowed edge's are its knots and window samples (:meth:`window`)."""
        e = np.repeat(np.arange(self.n_edges), np.diff(self.offsets))
        h = self.lo[e].astype(np.float64) + self.step[e].astype(np.float64) * self.codes.astype(np.float64)
        h[self.codes == NAN_CODE] = np.nan
        return h

    @property
    def resolution(self) -> float:
        """Largest quantisation error of the coded heights, mm (half the largest quantum)."""
        return float(self.step.max()) / 2.0 if self.n_edges else 0.0

    @property
    def n_points(self) -> int:
        """Number of e-points."""
        return int(self.codes.shape[0])

    @property
    def n_edges(self) -> int:
        """Number of grid edges carrying e-points."""
        return int(self.edge_ids.shape[0])

    @property
    def edge_ratio(self) -> float:
        """Share of all grid edges that carry e-points (Table 2's 'e-map ratio')."""
        return self.n_edges / edge_count(self.nx, self.ny)

    @property
    def nbytes(self) -> int:
        """Bytes of the stored e-map (:meth:`to_arrays`: one bit per grid edge saying which
        carry e-points, their point counts, codes, lo, step, and the cell patches). The
        int64 edge ids and offsets the kernels index by are rebuilt from the bits and counts
        on load (:attr:`index_nbytes`), as the evaluation tables are (:attr:`cache_nbytes`)."""
        return int(sum(a.nbytes for a in self.to_arrays().values()))

    @property
    def index_nbytes(self) -> int:
        """Bytes of the in-memory edge index (int64 ids and offsets), rebuilt on load."""
        return int(self.edge_ids.nbytes + self.offsets.nbytes)

    @property
    def patch_nbytes(self) -> int:
        """Bytes of the cell patches (0 without)."""
        return int(self.patches.nbytes) if self.patches is not None else 0

    @property
    def n_patches(self) -> int:
        """Number of base cells answered by a finer cell patch."""
        return int(self.patches.n_patches) if self.patches is not None else 0

    @property
    def n_lattices(self) -> int:
        """Number of patched cells answered by a dense lattice (the last resort)."""
        return int(np.count_nonzero(self.patches.level < 0)) if self.patches is not None else 0

    @property
    def cache_nbytes(self) -> int:
        """Bytes of the per-cell evaluation tables currently cached (0 before evaluate)."""
        return int(sum(a.nbytes for a in self._cache.get("arrays", {}).values()))

    def __repr__(self) -> str:
        return (f"EZMap({self.nx}x{self.ny} grid, {self.n_edges} edges ({100 * self.edge_ratio:.1f}%), "
                f"{self.n_points} points at <= {self.interval:g} mm, {self.n_patches} cell patches, "
                f"{self.nbytes / 1024:.1f} KB)")

    # ---- points ---------------------------------------------------------------------------

    def points(self) -> tuple[np.ndarray, np.ndarray]:
        """Local xy of every stored e-point, each ndarray of shape (P,), float64, in heights
        order (a windowed edge's knots where its spans place them)."""
        from . import _ez_kernels as _k

        px = np.empty(self.n_points)
        py = np.empty(self.n_points)
        _k.edge_points(self.edge_ids, self.offsets, self.x0, self.y0, self.dx, self.dy, self.nx, self.ny, px, py)
        full = self.full_counts()
        nxe = (self.nx - 1) * self.ny
        for k in np.flatnonzero(self.win >= 0):
            a, c, dl, dr = self.window(int(k))
            n = int(full[k])
            m = n + 1
            f = np.concatenate([np.arange(1, dl) * a / max(dl, 1), np.arange(max(a, 1), min(c, n) + 1),
                                c + np.arange(1, dr) * (m - c) / max(dr, 1)])
            eid = int(self.edge_ids[k])
            o0, o1 = int(self.offsets[k]), int(self.offsets[k + 1])
            if eid < nxe:
                i, j = divmod(eid, self.ny)
                px[o0:o1] = self.x0 + (i + f / m) * self.dx
            else:
                i, j = divmod(eid - nxe, self.ny - 1)
                py[o0:o1] = self.y0 + (j + f / m) * self.dy
        return px, py

    # ---- evaluation -----------------------------------------------------------------------

    def _check_base(self, base: ZMap) -> None:
        if not isinstance(base, ZMap):
            raise TypeError(f"base must be a zmap.ZMap, got {type(base).__name__}")
        if (base.nx, base.ny) != (self.nx, self.ny) or not np.allclose(
                (base.x0, base.y0, base.dx, base.dy), (self.x0, self.y0, self.dx, self.dy), rtol=0, atol=1e-12):
            raise ValueError(f"base grid {base.nx}x{base.ny} at ({base.x0}, {base.y0}) step ({base.dx}, {base.dy}) "
                             f"is not the e-map's {self.nx}x{self.ny} at ({self.x0}, {self.y0}) "
                             f"step ({self.dx}, {self.dy})")

    def _hq(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(codes, lo, step, cstart, win)`` as the kernels read samples
        (:func:`zmap.refine._edge_kernels._sample`); pass :meth:`_voff` as their offsets."""
        if self._cache.get("cstart_of") is not self.offsets:
            self._cache["cstart"] = np.ascontiguousarray(self.offsets[:-1])
            self._cache["cstart_of"] = self.offsets
        return (self.codes, self.lo, self.step, self._cache["cstart"], self.win)

    def _tables(self, base: ZMap) -> dict:
        """Per-edge breaks and per-cell traces, cached per base object."""
        key = (id(base), base.z.ctypes.data)
        if self._cache.get("key") == key:
            return self._cache["arrays"]
        from . import _ez_kernels as _k

        nx, ny = self.nx, self.ny
        E = self.n_edges
        kind = np.zeros(E, dtype=np.int8)
        brk_t = np.zeros(E, dtype=np.float64)
        jump_min, kink_min = break_thresholds(self.dx, self.dy, self.interval, self.tol)
        if E:
            _k.detect_breaks(base.z, self.edge_ids, self._voff(), self._hq(), self.forced, jump_min, kink_min,
                             BREAK_RATIO, kind, brk_t)
        # cells touching an e-edge, and the slot of each of their four edges
        ecell = np.flatnonzero(self.cell_mask().ravel()).astype(np.int64)
        ids = self.edge_ids
        nxe = (nx - 1) * ny
        ci, cj = ecell // (ny - 1), ecell % (ny - 1)
        want = np.stack([ci * ny + cj, nxe + (ci + 1) * (ny - 1) + cj, ci * ny + cj + 1,
                         nxe + ci * (ny - 1) + cj], axis=1)
        pos = np.searchsorted(ids, want)
        pos_c = np.minimum(pos, max(E - 1, 0))
        slots = np.where((pos < E) & (ids[pos_c] == want) if E else np.zeros(want.shape, bool), pos, -1)
        slots = np.ascontiguousarray(slots, dtype=np.int64)
        C = ecell.shape[0]
        nb = np.zeros(C, dtype=np.int8)
        bk = np.zeros((C, 2), dtype=np.int8)
        bt = np.zeros((C, 2), dtype=np.float64)
        pts = np.zeros((C, 3, 2), dtype=np.float64)
        arc = np.zeros((C, 3), dtype=np.float64)
        if C:
            _k.cell_geometry(ecell, slots, kind, brk_t, nx, ny, self.dx, self.dy, self.interval, nb, bk, bt, pts, arc)
        bub = np.zeros(C, dtype=np.float64)
        if self.bub_cells.size and C:
            at = np.minimum(np.searchsorted(ecell, self.bub_cells), C - 1)
            on = ecell[at] == self.bub_cells
            bub[at[on]] = self.bub_h[on]
        arrays = {"brk_kind": kind, "brk_t": brk_t, "ecell_ids": ecell, "slots": slots, "nb": nb, "bk": bk,
                  "bt": bt, "pts": pts, "arc": arc, "bub": bub}
        self._cache["key"] = key
        self._cache["arrays"] = arrays
        return arrays

    def cell_mask(self) -> np.ndarray:
        """Cells where :meth:`evaluate` answers, ndarray of shape (nx-1, ny-1), bool.

        These are the cells with e-points on any edge, and the ring around them whose base
        Bezier stencil (the outer edges their corner slopes use) holds an e-edge: there the
        edge curves take their slopes from the side away from a break, so that no cell
        blends base heights across a wall or a sharp edge.
        """
        m = cells_around(self.nx, self.ny, self.edge_ids)
        if self.patches is not None and self.patches.n_patches:
            m.ravel()[self.patches.cells] = True
        return m

    # ---- evaluation helpers ------------------------------------------------------------------

    def breaks(self, base: ZMap) -> tuple[np.ndarray, np.ndarray]:
        """Break found on each e-edge: ``kind`` (E,) int8 (0 none, 1 jump, 2 kink) and
        ``t`` (E,) float64, the parameter along the edge from its first grid point."""
        self._check_base(base)
        a = self._tables(base)
        return a["brk_kind"].copy(), a["brk_t"].copy()

    def coons_cells(self, base: ZMap, cells: np.ndarray) -> np.ndarray:
        """The ``cells`` (flat ids) that :meth:`evaluate` answers with a Coons patch (e-cells
        not split by a trace), sorted."""
        self._check_base(base)
        cells = np.unique(np.asarray(cells, dtype=np.int64))
        if not self.n_edges or cells.size == 0:
            return cells[:0]
        a = self._tables(base)
        ec = a["ecell_ids"]
        if ec.size == 0:
            return cells[:0]
        at = np.minimum(np.searchsorted(ec, cells), ec.size - 1)
        on = ec[at] == cells
        P = a["pts"][at]
        split = (a["nb"][at] == 2) & ((P[:, 0, 0] != P[:, 2, 0]) | (P[:, 0, 1] != P[:, 2, 1]))
        return cells[on & ~split]

    def evaluate(self, base: ZMap, x, y) -> np.ndarray:
        """Heights in the cells of :meth:`cell_mask`; NaN elsewhere (use the base there).

        Those are the cells with e-points on any edge and the ring of cells whose base
        stencil reaches an e-edge (their plain edges take slopes from the side away from a
        break), so that no base cell blends heights across a wall or a sharp edge.

        Parameters
        ----------
        base : ZMap
            The base z-map the e-map was built on (same grid and frame).
        x, y : array_like of float, broadcastable
            World coordinates, mm.

        Returns
        -------
        ndarray of float64, broadcast shape of x and y (float for scalars)
            Heights in mm; NaN outside e-cells, outside the map, in cells with a missing
            corner height, and where a needed e-point has no height.

        Examples
        --------
        >>> import numpy as np
        >>> from zmap import ZMap
        >>> from zmap.refine.ez import build_ez
        >>> f = lambda x, y: 0.3 * x - 0.2 * y + np.where(y > 0.7 * x + 0.1, 4.0, 0.0)
        >>> base = ZMap.from_function(f, (0, 0, 2, 2), 0.5)
        >>> ez = build_ez(base, f, tol=0.01)
        >>> x, y = np.array([0.9, 1.0]), np.array([0.4, 1.3])
        >>> bool(np.abs(ez.evaluate(base, x, y) - f(x, y)).max() < 2 * ez.resolution)
        True
        """
        from . import _ez_kernels as _k

        self._check_base(base)
        xb, yb = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
        shape = xb.shape
        xs = np.ascontiguousarray(xb).ravel()
        ys = np.ascontiguousarray(yb).ravel()
        out = np.full(xs.shape[0], np.nan)
        if self.n_edges and xs.size:
            a = self._tables(base)
            kernel = _k.ez_kernel if xs.size >= SERIAL_BELOW else _k.ez_kernel_serial
            kernel(base.z, base.x0, base.y0, base.dx, base.dy, math.cos(base.angle), math.sin(base.angle),
                         base.origin[0], base.origin[1], xs, ys, self.edge_ids, self._voff(), self._hq(), a["brk_kind"],
                         a["brk_t"], a["ecell_ids"], a["slots"], a["nb"], a["bk"], a["bt"], a["pts"], a["arc"], a["bub"],
                         out)
        if self.n_patches and xs.size:
            self.patches.evaluate(base, self.interval, self.tol, xs, ys, out)
        out = out.reshape(shape)
        return out[()] if out.ndim == 0 else out

    def height(self, base: ZMap, x, y) -> np.ndarray:
        """EZ model heights everywhere: :meth:`evaluate` in e-cells, the base's Bezier
        elsewhere (the scheme the e-cells' plain edges follow)."""
        from ..interpolate import bezier

        h = np.asarray(self.evaluate(base, x, y), dtype=np.float64)
        miss = np.isnan(h)
        if miss.any():
            xb, yb = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
            h = np.array(h, copy=True).reshape(xb.shape)
            h[miss] = bezier(base, xb[miss], yb[miss])
        return h[()] if h.ndim == 0 else h

    # ---- storage --------------------------------------------------------------------------

    def edge_bits(self) -> np.ndarray:
        """One bit per grid edge (edge id order, :func:`numpy.packbits`): set on the e-edges."""
        bits = np.zeros(edge_count(self.nx, self.ny), dtype=np.uint8)
        bits[self.edge_ids] = 1
        return np.packbits(bits)

    def to_arrays(self) -> dict[str, np.ndarray]:
        """Arrays to save inside another file; :meth:`from_arrays` restores the map exactly."""
        return {
            "version": np.array([FORMAT_VERSION], dtype=np.int64),
            "grid": np.array([self.x0, self.y0, self.dx, self.dy, self.interval, self.tol], dtype=np.float64),
            "shape": np.array([self.nx, self.ny, self.failed, self.lifted, self.unresolved, self.pruned],
                              dtype=np.int64),
            "edge_bits": self.edge_bits(),
            **pack_edge_counts(np.diff(self.offsets)),
            **{f"codes_{k}": v for k, v in pack_codes(self.codes, self.offsets).items()},
            **pack_offsets(self.lo, QUANTUM_SHARE * self.tol),
            **_pack_steps(self.step),
        } | pack_windows(self.win, self.forced) | pack_bubbles(self.bub_cells, self.bub_h, self.tol) | {
            f"patch_{k}": v for k, v in (self.patches or CellPatches.empty()).to_arrays().items()}

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray]) -> EZMap:
        """Inverse of :meth:`to_arrays`."""
        missing = {"version", "grid", "shape"} - set(arrays)
        if "lo" not in arrays and "lo_k" not in arrays:
            missing.add("lo")
        if "step" not in arrays and "step_common" not in arrays:
            missing.add("step")
        if "codes" not in arrays and "codes_bits" not in arrays:
            missing.add("codes")
        if "edge_bits" in arrays:
            missing |= set() if "counts" in arrays else {"counts_b", "counts_w"} - set(arrays)
        elif "counts" in arrays:
            missing.add("edge_bits")
        else:
            missing |= {"edge_ids", "offsets"} - set(arrays)
        if missing:
            raise ValueError(f"e-map arrays lack {sorted(missing)}, got {sorted(arrays)}")
        version = int(np.asarray(arrays["version"]).ravel()[0])
        if not 1 <= version <= FORMAT_VERSION:
            raise ValueError(f"e-map format version {version} is not supported (this zmap reads 1..{FORMAT_VERSION})")
        g = np.asarray(arrays["grid"], dtype=np.float64).ravel()
        s = np.asarray(arrays["shape"], dtype=np.int64).ravel()
        patches = None
        if version >= 2:
            patches = CellPatches.from_arrays({k[len("patch_"):]: v for k, v in arrays.items()
                                               if k.startswith("patch_")}, grid=(g[2], g[3], g[4]))
            patches = patches if patches.n_patches else None
        if "edge_bits" in arrays:
            nx, ny = int(s[0]), int(s[1])
            bits = np.unpackbits(np.asarray(arrays["edge_bits"], dtype=np.uint8), count=edge_count(nx, ny))
            edge_ids = np.flatnonzero(bits).astype(np.int64)
            counts = (_unpack_bits(arrays["counts_b"], edge_ids.size, int(np.asarray(arrays["counts_w"]).ravel()[0]),
                                   "point counts") if "counts_b" in arrays
                      else np.asarray(arrays["counts"]).astype(np.int64))
            if counts.shape != edge_ids.shape:
                raise ValueError(f"e-map arrays: {counts.size} point counts for {edge_ids.size} edges")
            offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
            nxe = (nx - 1) * ny
            full = np.where(edge_ids < nxe, _n_points(g[2], g[4]), _n_points(g[3], g[4]))
            win = unpack_windows(arrays, edge_ids, counts, full)
        else:
            edge_ids, offsets, win = arrays["edge_ids"], arrays["offsets"], None
        codes = (unpack_codes(arrays["codes_bits"], arrays["codes_w4"], offsets, arrays.get("codes_mode"),
                              arrays.get("codes_r4")) if "codes_bits" in arrays else arrays["codes"])
        bub_cells, bub_h = unpack_bubbles(arrays)
        return cls(g[0], g[1], g[2], g[3], int(s[0]), int(s[1]), g[4], g[5], edge_ids, offsets,
                   codes, unpack_offsets(arrays, edge_ids.size), _unpack_steps(arrays, edge_ids.size), failed=int(s[2]), lifted=int(s[3]) if s.size > 3 else 0,
                   patches=patches, unresolved=int(s[4]) if s.size > 4 else 0, pruned=int(s[5]) if s.size > 5 else 0,
                   win=win, bub_cells=bub_cells, bub_h=bub_h)


class CellPatches(CellPatchData):
    """Finer EZ-maps over single base cells (levels, lattices and storage: see
    :mod:`zmap.refine.patch`), evaluated: each EZ patch as an :class:`EZMap` over its cell's
    sub-grid, a lattice bilinearly. The fields, the storage and the lattices' heights are
    :class:`zmap.refine._patches.CellPatchData`'s.
    """

    # ---- evaluation -----------------------------------------------------------------------

    def _patch_maps(self, k: int, base: ZMap, interval: float, tol: float) -> tuple[ZMap, EZMap]:
        """The sub-grid ZMap and EZMap of EZ patch ``k``."""
        m = int(self.level[k])
        sub = sub_grid(base, int(self.cells[k]), m, self.nodes[self.node_off[k]:self.node_off[k + 1]].reshape(m + 1, m + 1))
        ids, _ = all_edges(sub, interval)
        offsets = np.zeros(ids.size + 1, dtype=np.int64)
        np.cumsum(self.counts[self.edge_off[k]:self.edge_off[k + 1]], out=offsets[1:])
        ez = EZMap(sub.x0, sub.y0, sub.dx, sub.dy, m + 1, m + 1, interval, tol, ids, offsets,
                   self.codes[self.code_off[k]:self.code_off[k + 1]], self.lo[self.edge_off[k]:self.edge_off[k + 1]],
                   self.step[self.edge_off[k]:self.edge_off[k + 1]])
        return sub, ez

    def _stacks(self, base: ZMap, interval: float, tol: float) -> dict[int, dict]:
        """Per EZ level, the patches' sub-grids and evaluation tables stacked (built once).

        Every patch of a level has the same sub-edges, points and cells, so one kernel
        call evaluates them all (:func:`zmap.refine._ez_kernels.patch_kernel`).
        """
        key = (id(base), base.z.ctypes.data, interval, tol)
        if self._maps.get("key") == key:
            return self._maps["stacks"]
        stacks = {}
        for m in np.unique(self.level[self.level > 0]):
            index = np.flatnonzero(self.level == m)
            maps = [self._patch_maps(int(k), base, interval, tol) for k in index]
            tabs = [ez._tables(sub) for sub, ez in maps]
            sub0, ez0 = maps[0]
            st = {name: np.ascontiguousarray(np.stack([t[name] for t in tabs]))
                  for name in ("brk_kind", "brk_t", "nb", "bk", "bt", "pts", "arc")}
            P = max(ez.n_points for _, ez in maps)
            codes = np.full((len(maps), max(P, 1)), NAN_CODE, dtype=np.uint16)
            for r, (_, ez) in enumerate(maps):
                codes[r, :ez.n_points] = ez.codes
            st.update(index=index, zs=np.ascontiguousarray(np.stack([sub.z for sub, _ in maps])),
                      x0s=np.array([sub.x0 for sub, _ in maps]), y0s=np.array([sub.y0 for sub, _ in maps]),
                      dx=sub0.dx, dy=sub0.dy, edge_ids=ez0.edge_ids, nowin=np.full(ez0.n_edges, -1, np.int64),
                      offsets=np.ascontiguousarray(np.stack([ez.offsets for _, ez in maps])),
                      ecell_ids=tabs[0]["ecell_ids"], slots=tabs[0]["slots"], codes=codes,
                      lo=np.ascontiguousarray(np.stack([ez.lo for _, ez in maps])),
                      step=np.ascontiguousarray(np.stack([ez.step for _, ez in maps])))
            stacks[int(m)] = st
        self._maps = {"key": key, "stacks": stacks}
        return stacks

    def evaluate(self, base: ZMap, interval: float, tol: float, x: np.ndarray, y: np.ndarray,
                 out: np.ndarray) -> None:
        """Overwrite ``out`` where a point lies in a patched cell and its patch has a height.

        ``x``, ``y``, ``out``: flat float64 arrays, world xy.
        """
        from . import _ez_kernels as _k

        if not self.n_patches or x.size == 0:
            return
        lx, ly = base.world_to_local(x, y)
        # a NaN point (a caller's "no point") lies in no cell: -1, not the cast of NaN
        fi = np.floor((lx - base.x0) / base.dx)
        fj = np.floor((ly - base.y0) / base.dy)
        i = np.where(np.isfinite(fi), fi, -1).astype(np.int64)
        j = np.where(np.isfinite(fj), fj, -1).astype(np.int64)
        # points on the map's far edges belong to the last cell, as in the kernels
        i = np.where(i == base.nx - 1, base.nx - 2, i)
        j = np.where(j == base.ny - 1, base.ny - 2, j)
        inside = (i >= 0) & (i <= base.nx - 2) & (j >= 0) & (j <= base.ny - 2)
        cid = np.where(inside, i * (base.ny - 1) + j, -1)
        pos = np.minimum(np.searchsorted(self.cells, cid), self.n_patches - 1)
        hit = np.flatnonzero(inside & (self.cells[pos] == cid))
        if hit.size == 0:
            return
        k = pos[hit]
        level = self.level[k]
        h = np.full(hit.size, np.nan)
        lat = level < 0
        if lat.any():
            h[lat] = self._lattice(k[lat], base, lx[hit[lat]], ly[hit[lat]])
        if not lat.all():
            c, s_ = math.cos(base.angle), math.sin(base.angle)
            for m, st in self._stacks(base, interval, tol).items():
                sel = np.flatnonzero(level == m)
                if sel.size == 0:
                    continue
                ks = np.searchsorted(st["index"], k[sel])
                hs = np.empty(sel.size)
                kernel = _k.patch_kernel if sel.size >= SERIAL_BELOW else _k.patch_kernel_serial
                kernel(st["zs"], st["x0s"], st["y0s"], st["dx"], st["dy"], c, s_, base.origin[0], base.origin[1],
                       np.ascontiguousarray(x[hit[sel]]), np.ascontiguousarray(y[hit[sel]]), ks, st["edge_ids"],
                       st["offsets"], st["codes"], st["lo"], st["step"], st["brk_kind"], st["brk_t"], st["ecell_ids"],
                       st["slots"], st["nb"], st["bk"], st["bt"], st["pts"], st["arc"], st["nowin"], hs)
                h[sel] = hs
        if self.subs is not None and self.subs.n:
            h = self.subs.override(cid[hit], base, lx[hit], ly[hit], h)
        ok = ~np.isnan(h)
        out[hit[ok]] = h[ok]
