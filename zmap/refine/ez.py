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
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .. import features
from ..errors import RefineError
from ..grid import ZMap

__all__ = ["NAN_CODE", "EZMap", "build_ez", "edge_count", "encode_heights"]

FORMAT_VERSION = 2
#: An edge whose e-points all lie within this share of the tolerance of the base's Bezier
#: curve along it carries nothing the base misses, and is dropped (``build_ez(prune=True)``).
PRUNE_SHARE = 0.25
#: Batches smaller than this are evaluated on one thread (no thread-pool wake-up).
SERIAL_BELOW = 4096
#: A jump or kink must stand out this many times from its neighbours to count as a break.
BREAK_RATIO = 4.0


def edge_count(nx: int, ny: int) -> int:
    """Number of grid edges of an ``nx`` by ``ny`` grid: ``(nx-1)*ny + nx*(ny-1)``."""
    return (nx - 1) * ny + nx * (ny - 1)


#: 16-bit code of an e-point with no height; valid codes are 0 .. NAN_CODE - 1.
NAN_CODE = 65535


def encode_heights(offsets: np.ndarray, heights: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """16-bit codes of e-point heights, per edge ``height = lo + step * code``.

    Parameters
    ----------
    offsets : ndarray of shape (E+1,), int64
        CSR offsets of the edges (each edge owns at least one point).
    heights : ndarray of shape (P,), float64
        Heights in mm, NaN = none.

    Returns
    -------
    codes : ndarray of shape (P,), uint16
        ``round((height - lo) / step)``, :data:`NAN_CODE` for NaN.
    lo, step : ndarray of shape (E,), float32
        The edge's lowest height and its range over ``NAN_CODE - 1`` steps.

    Examples
    --------
    >>> c, lo, st = encode_heights(np.array([0, 3]), np.array([1.0, np.nan, 3.0]))
    >>> c.tolist(), lo.tolist(), float(lo[0] + st[0] * c[2])
    ([0, 65535, 65534], [1.0], 3.0)
    """
    E = offsets.shape[0] - 1
    if E == 0:
        return np.zeros(0, np.uint16), np.zeros(0, np.float32), np.zeros(0, np.float32)
    starts = offsets[:-1]
    finite = ~np.isnan(heights)
    lo = np.minimum.reduceat(np.where(finite, heights, np.inf), starts)
    hi = np.maximum.reduceat(np.where(finite, heights, -np.inf), starts)
    none = ~np.isfinite(lo)
    lo[none] = 0.0
    hi[none] = 0.0
    lo32 = lo.astype(np.float32)
    span = np.maximum(hi - lo32.astype(np.float64), 0.0)
    step32 = (span / (NAN_CODE - 1)).astype(np.float32)
    e = np.repeat(np.arange(E), np.diff(offsets))
    st = step32[e].astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        q = np.where(st > 0, np.rint((heights - lo32[e].astype(np.float64)) / np.where(st > 0, st, 1.0)), 0.0)
    q = np.clip(np.nan_to_num(q, nan=0.0), 0, NAN_CODE - 1)
    codes = q.astype(np.uint16)
    codes[~finite] = NAN_CODE
    return codes, lo32, step32


def cells_around(nx: int, ny: int, ids: np.ndarray) -> np.ndarray:
    """Cells next to the grid edges ``ids`` and the ring whose Bezier stencil reaches them.

    Returns a bool ndarray of shape (nx-1, ny-1).
    """
    nxe = (nx - 1) * ny
    is_x = ids < nxe
    a, r = ids[is_x] // ny, ids[is_x] % ny
    yi, yb = (ids[~is_x] - nxe) // (ny - 1), (ids[~is_x] - nxe) % (ny - 1)
    # x-edge (a, r): own cells (a, r), (a, r-1); stencil ring (a+-1, r), (a+-1, r-1)
    # y-edge (yi, yb): own cells (yi, yb), (yi-1, yb); ring (yi, yb+-1), (yi-1, yb+-1)
    ci = np.concatenate([a, a, a + 1, a + 1, a - 1, a - 1, yi, yi - 1, yi, yi - 1, yi, yi - 1])
    cj = np.concatenate([r, r - 1, r, r - 1, r, r - 1, yb, yb, yb + 1, yb + 1, yb - 1, yb - 1])
    ok = (ci >= 0) & (ci <= nx - 2) & (cj >= 0) & (cj <= ny - 2)
    m = np.zeros((nx - 1) * (ny - 1), dtype=bool)
    m[ci[ok] * (ny - 1) + cj[ok]] = True
    return m.reshape(nx - 1, ny - 1)


def _empty_patches():
    from .patch import CellPatches

    return CellPatches.empty()


def _n_points(length: float, interval: float) -> int:
    """Interior points that split ``length`` into pieces no longer than ``interval``."""
    return max(math.ceil(length / interval - 1e-9) - 1, 0)


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

    Examples
    --------
    >>> import numpy as np
    >>> from zmap import ZMap
    >>> f = lambda x, y: np.where(x > 1.23, 5.0, 0.0)
    >>> base = ZMap.from_function(f, (0, 0, 3, 3), 0.5)
    >>> ez = build_ez(base, f, tol=0.01)
    >>> round(float(ez.evaluate(base, 1.225, 1.6)), 6), round(float(ez.evaluate(base, 1.235, 1.6)), 6)
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
    _cache: dict = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        self.x0, self.y0, self.dx, self.dy = (float(v) for v in (self.x0, self.y0, self.dx, self.dy))
        self.nx, self.ny, self.failed, self.lifted = int(self.nx), int(self.ny), int(self.failed), int(self.lifted)
        self.unresolved, self.pruned = int(self.unresolved), int(self.pruned)
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

    # ---- figures --------------------------------------------------------------------------

    @classmethod
    def from_heights(cls, x0: float, y0: float, dx: float, dy: float, nx: int, ny: int, interval: float, tol: float,
                     edge_ids: np.ndarray, offsets: np.ndarray, heights: np.ndarray, **kwargs) -> EZMap:
        """The e-map of e-point ``heights`` (float, NaN = none; shape (P,)), coded to 16 bits."""
        codes, lo, step = encode_heights(np.asarray(offsets, dtype=np.int64), np.asarray(heights, dtype=np.float64))
        return cls(x0, y0, dx, dy, nx, ny, interval, tol, edge_ids, offsets, codes, lo, step, **kwargs)

    @property
    def heights(self) -> np.ndarray:
        """Decoded e-point heights, ndarray of shape (P,), float64, mm (NaN = none)."""
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
        """Bytes of the stored e-map (edge ids, offsets, codes, lo, step, cell patches); the
        evaluation cache, rebuilt from them, is :attr:`cache_nbytes`."""
        return int(self.edge_ids.nbytes + self.offsets.nbytes + self.codes.nbytes + self.lo.nbytes + self.step.nbytes
                   + self.patch_nbytes)

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
        """Local xy of every e-point, each ndarray of shape (P,), float64, in heights order."""
        from . import _ez_kernels as _k

        px = np.empty(self.n_points)
        py = np.empty(self.n_points)
        _k.edge_points(self.edge_ids, self.offsets, self.x0, self.y0, self.dx, self.dy, self.nx, self.ny, px, py)
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

    def _hq(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return (self.codes, self.lo, self.step)

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
        n_max = max(_n_points(self.dx, self.interval), _n_points(self.dy, self.interval)) + 1
        h = max(self.dx, self.dy)
        jump_min = self.tol
        kink_min = 4.0 * self.tol * (h / n_max) / h
        if E:
            _k.detect_breaks(base.z, self.edge_ids, self.offsets, self._hq(), jump_min, kink_min, BREAK_RATIO,
                             kind, brk_t)
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
        arrays = {"brk_kind": kind, "brk_t": brk_t, "ecell_ids": ecell, "slots": slots, "nb": nb, "bk": bk,
                  "bt": bt, "pts": pts, "arc": arc}
        self._cache = {"key": key, "arrays": arrays}
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
                         base.origin[0], base.origin[1], xs, ys, self.edge_ids, self.offsets, self._hq(), a["brk_kind"],
                         a["brk_t"], a["ecell_ids"], a["slots"], a["nb"], a["bk"], a["bt"], a["pts"], a["arc"], out)
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

    def to_arrays(self) -> dict[str, np.ndarray]:
        """Arrays to save inside another file; :meth:`from_arrays` restores the map exactly."""
        return {
            "version": np.array([FORMAT_VERSION], dtype=np.int64),
            "grid": np.array([self.x0, self.y0, self.dx, self.dy, self.interval, self.tol], dtype=np.float64),
            "shape": np.array([self.nx, self.ny, self.failed, self.lifted, self.unresolved, self.pruned],
                              dtype=np.int64),
            "edge_ids": self.edge_ids,
            "offsets": self.offsets,
            "codes": self.codes,
            "lo": self.lo,
            "step": self.step,
        } | {f"patch_{k}": v for k, v in (self.patches or _empty_patches()).to_arrays().items()}

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray]) -> EZMap:
        """Inverse of :meth:`to_arrays`."""
        missing = {"version", "grid", "shape", "edge_ids", "offsets", "codes", "lo", "step"} - set(arrays)
        if missing:
            raise ValueError(f"e-map arrays lack {sorted(missing)}, got {sorted(arrays)}")
        version = int(np.asarray(arrays["version"]).ravel()[0])
        if not 1 <= version <= FORMAT_VERSION:
            raise ValueError(f"e-map format version {version} is not supported (this zmap reads 1..{FORMAT_VERSION})")
        g = np.asarray(arrays["grid"], dtype=np.float64).ravel()
        s = np.asarray(arrays["shape"], dtype=np.int64).ravel()
        patches = None
        if version >= 2:
            from .patch import CellPatches

            patches = CellPatches.from_arrays({k[len("patch_"):]: v for k, v in arrays.items()
                                               if k.startswith("patch_")})
            patches = patches if patches.n_patches else None
        return cls(g[0], g[1], g[2], g[3], int(s[0]), int(s[1]), g[4], g[5], arrays["edge_ids"], arrays["offsets"],
                   arrays["codes"], arrays["lo"], arrays["step"], failed=int(s[2]), lifted=int(s[3]) if s.size > 3 else 0,
                   patches=patches, unresolved=int(s[4]) if s.size > 4 else 0, pruned=int(s[5]) if s.size > 5 else 0)


def build_ez(base: ZMap, heights: Callable[[np.ndarray, np.ndarray], np.ndarray], *, tol: float,
             eps_r: float | None = None, se_curves: Sequence[np.ndarray] = (), interval: float | None = None,
             prune: bool = True, verify: bool = True) -> EZMap:
    """Procedure Construct_EZmap: e-points on the steep and SE-crossed edges of ``base``.

    Beyond the paper, two steps that a real die needs (both on by default):

    - ``prune``: a candidate edge whose e-points all lie within ``PRUNE_SHARE * tol`` of the
      base's cubic Bezier curve along it is dropped (a steep but smooth slope the base
      already holds; on free-form parts most steep edges are such);
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
    prune, verify : bool
        Drop the edges the base holds; check the refined cells and patch the misses.

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
    >>> ez.n_points // ez.n_edges, ez.failed
    (49, 0)
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
        ez.lifted = int(lifted.sum())
        ez.codes, ez.lo, ez.step = encode_heights(offsets, z)
    ez.pruned = int(n_candidates - ez.n_edges)
    if verify and n_candidates:
        from .patch import patch_failing

        # the refined cells, and the cells a sharp edge crosses (a rib between the probes)
        cells = np.flatnonzero((cells_around(nx, ny, se_ids) | ez.cell_mask()).ravel()).astype(np.int64)

        def install(p):
            ez.patches = p if p.n_patches else None
            ez._cache = {}

        a = ez._tables(base) if ez.n_edges else None
        broken = a["ecell_ids"][a["nb"] > 0] if a is not None else None
        _patches, still = patch_failing(lambda x, y: ez.height(base, x, y), base, heights, tol, interval, cells,
                                        install, fine_cells=broken)
        ez.unresolved = int(still.size)
    return ez


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
