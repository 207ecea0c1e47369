"""Dexel workpiece: the extended z-buffer of papers 000 and 001, as flat arrays.

A grid of vertical rays at a fixed pitch covers the stock's xy; ray ``(i, j)`` stands at
``(x0 + i*pitch, y0 + j*pitch)`` and holds a sorted list of disjoint material intervals
(dexels) ``[near, far]`` in mm, near < far, bottom-up. The lists live in fixed slots
``near[r, :cnt[r]]``, ``far[r, :cnt[r]]`` with ``r = i*ny + j``; the slot count grows (doubles)
when a cut splits a dexel in a full ray. Heights are float32 (about 4 µm at 33 mm), so a
reconstruction from a history is bit-identical to a fresh simulation.

The cutter occupies, along a ray at distance ``d`` from its axis, ``[tip_z + envelope(d),
tip_z + length]``; a stage removes the union of that over its path piece, the exact swept
volume (:mod:`zmap.sim._sweep_kernels`), rounded up to float32 so that the stock never lies
below the exact sweep. Subtracting it covers the four cases of paper 001 (create by split,
delete, shorten the front, shorten the back).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from ..gridspec import lines_within
from . import _dexel_kernels as _k

__all__ = ["DexelWorkpiece", "cutter_table"]


#: dexel slots per ray of a new stock: one (a cut from above never splits a dexel); a ray
#: that needs more makes all rays twice as wide (:meth:`DexelWorkpiece.grow`)
START_SLOTS = 1


def cutter_table(cutters: Sequence[Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Kernel arrays ``(code, radius, corner_radius, length)`` of a list of cutters.

    Parameters
    ----------
    cutters : sequence of zmap.sim.tools.Cutter
        Cutters; position tool slots index this list.

    Returns
    -------
    code : ndarray of shape (m,), int32
    radius, corner_radius, length : ndarray of shape (m,), float64, mm
    """
    code = np.array([int(c.code) for c in cutters], dtype=np.int32)
    radius = np.array([float(c.radius) for c in cutters], dtype=np.float64)
    corner = np.array([float(c.corner_radius) for c in cutters], dtype=np.float64)
    length = np.array([float(c.length) for c in cutters], dtype=np.float64)
    return code, radius, corner, length


def _empty_history_args() -> tuple:
    i4 = np.zeros((1, 1), dtype=np.int32)
    f = np.zeros(1, dtype=np.float32)
    i = np.zeros(1, dtype=np.int32)
    return (False, i4, i4, f, i, i, i, False, f, i, i, False, i4, f, i, i, i)


@dataclass(eq=False)
class DexelWorkpiece:
    """Extended z-buffer over a regular grid of vertical rays.

    Parameters
    ----------
    x0, y0 : float
        Position of ray (0, 0) in mm.
    pitch : float
        Ray spacing in mm, the same along x and y.
    nx, ny : int
        Rays along x and y.
    near, far : ndarray of shape (nx*ny, K), float32
        Dexel bounds in mm, ray ``r = i*ny + j``; slots past ``cnt[r]`` are unused.
    cnt : ndarray of shape (nx*ny,), int32
        Dexels per ray.
    created, deleted : int
        Dexels created by splits and deleted by cuts so far.

    Examples
    --------
    >>> wp = DexelWorkpiece.from_box((0, 0, -5, 2, 1, 0), pitch=0.5)
    >>> wp.shape, wp.n_dexels, wp.intervals(0, 0).tolist()
    ((5, 3), 15, [[-5.0, 0.0]])
    """

    x0: float
    y0: float
    pitch: float
    nx: int
    ny: int
    near: np.ndarray
    far: np.ndarray
    cnt: np.ndarray
    created: int = 0
    deleted: int = 0

    # ---- construction -------------------------------------------------------------------

    @classmethod
    def from_box(cls, bounds: Sequence[float], pitch: float = 0.26) -> "DexelWorkpiece":
        """A box stock ``bounds = (x0, y0, z0, x1, y1, z1)`` in mm, rays at ``pitch``.

        Rays start at ``(x0, y0)`` and cover the box up to ``x1``, ``y1``; each holds one
        dexel ``[z0, z1]``.
        """
        b = [float(v) for v in bounds]
        if len(b) != 6 or not all(math.isfinite(v) for v in b):
            raise ValueError(f"box bounds must be 6 finite numbers (x0, y0, z0, x1, y1, z1), got {tuple(b)!r}")
        x0, y0, z0, x1, y1, z1 = b
        if not (x1 > x0 and y1 > y0 and z1 > z0):
            raise ValueError(f"box bounds must satisfy x0 < x1, y0 < y1, z0 < z1, got {tuple(b)}")
        pitch = _check_pitch(pitch)
        nx, ny = lines_within(x0, x1, pitch), lines_within(y0, y1, pitch)  # rays stay inside the block
        if np.float32(z0) >= np.float32(z1):
            raise ValueError(f"box is thinner than float32 resolution: z0={z0}, z1={z1}")
        near = np.full((nx * ny, START_SLOTS), np.float32(z0), dtype=np.float32)
        far = np.full((nx * ny, START_SLOTS), np.float32(z1), dtype=np.float32)
        cnt = np.ones(nx * ny, dtype=np.int32)
        return cls(x0, y0, pitch, nx, ny, near, far, cnt)

    @classmethod
    def from_zmap(cls, zm: Any, *, pitch: float | None = None, bottom: float | None = None) -> "DexelWorkpiece":
        """Stock below the surface of a ZMap: per ray one dexel ``[bottom, z(x, y)]``.

        Parameters
        ----------
        zm : zmap.ZMap
            Surface; NaN heights (no surface) give empty rays. Maps with a local frame
            are not supported.
        pitch : float, optional
            Ray pitch in mm; default the map's ``dx`` (then rays sit on its grid points and
            take its heights exactly); otherwise heights are bilinear, NaN near a hole.
        bottom : float, optional
            Bottom of the stock in mm; default ``nanmin(z) - max(1, 0.1 * (nanmax - nanmin))``.
        """
        if getattr(zm, "has_frame", False):
            raise ValueError("a ZMap with a local frame (angle/origin) cannot be a stock; resample it first")
        z = np.asarray(zm.z, dtype=np.float64)
        if np.all(np.isnan(z)):
            raise ValueError("the ZMap has no surface (all heights are NaN)")
        zmin, zmax = float(np.nanmin(z)), float(np.nanmax(z))
        if bottom is None:
            bottom = zmin - max(1.0, 0.1 * (zmax - zmin))
        bottom = float(bottom)
        if not math.isfinite(bottom):
            raise ValueError(f"bottom must be finite, got {bottom!r}")
        pitch = _check_pitch(zm.dx if pitch is None else pitch)
        nx, ny = lines_within(zm.x0, zm.x1, pitch), lines_within(zm.y0, zm.y1, pitch)
        if pitch == zm.dx and pitch == zm.dy:
            top = z[:nx, :ny]
        else:
            fi = np.arange(nx) * pitch / zm.dx
            fj = np.arange(ny) * pitch / zm.dy
            i0 = np.clip(np.floor(fi).astype(int), 0, zm.nx - 2)
            j0 = np.clip(np.floor(fj).astype(int), 0, zm.ny - 2)
            u = (fi - i0)[:, None]
            v = (fj - j0)[None, :]
            I, J = i0[:, None], j0[None, :]
            top = ((1 - u) * (1 - v) * z[I, J] + u * (1 - v) * z[I + 1, J]
                   + (1 - u) * v * z[I, J + 1] + u * v * z[I + 1, J + 1])
        top32 = top.astype(np.float32).ravel()
        b32 = np.float32(bottom)
        near = np.full((nx * ny, START_SLOTS), b32, dtype=np.float32)
        far = np.zeros((nx * ny, START_SLOTS), dtype=np.float32)
        far[:, 0] = top32
        cnt = (top32 > b32).astype(np.int32)  # NaN compares False: empty ray
        return cls(float(zm.x0), float(zm.y0), pitch, nx, ny, near, far, cnt)

    @classmethod
    def from_csr(cls, x0: float, y0: float, pitch: float, nx: int, ny: int, offsets: np.ndarray,
                 near: np.ndarray, far: np.ndarray, created: int = 0, deleted: int = 0) -> "DexelWorkpiece":
        """Build from compact per-ray lists: ray r owns ``near[offsets[r]:offsets[r+1]]``."""
        from . import _csr_kernels

        offsets = np.ascontiguousarray(offsets, dtype=np.int64)
        n = int(nx) * int(ny)
        if offsets.shape != (n + 1,):
            raise ValueError(f"offsets has shape {offsets.shape}, expected ({n + 1},) for {nx} x {ny} rays")
        K = max(START_SLOTS, int(np.diff(offsets).max(initial=0)))
        n_near = np.zeros((n, K), dtype=np.float32)
        n_far = np.zeros((n, K), dtype=np.float32)
        cnt = np.empty(n, dtype=np.int32)
        _csr_kernels.scatter(np.arange(n, dtype=np.int64), offsets, np.ascontiguousarray(near, dtype=np.float32),
                             np.ascontiguousarray(far, dtype=np.float32), n_near, n_far, cnt)
        return cls(float(x0), float(y0), float(pitch), int(nx), int(ny), n_near, n_far, cnt,
                   int(created), int(deleted))

    # ---- geometry -----------------------------------------------------------------------

    @property
    def shape(self) -> tuple[int, int]:
        return (self.nx, self.ny)

    @property
    def n_rays(self) -> int:
        return self.nx * self.ny

    @property
    def n_dexels(self) -> int:
        return int(self.cnt.sum())

    @property
    def slots(self) -> int:
        return int(self.near.shape[1])

    @property
    def x(self) -> np.ndarray:
        return self.x0 + self.pitch * np.arange(self.nx)

    @property
    def y(self) -> np.ndarray:
        return self.y0 + self.pitch * np.arange(self.ny)

    @property
    def nbytes(self) -> int:
        """Bytes held by the dexel arrays."""
        return int(self.near.nbytes + self.far.nbytes + self.cnt.nbytes)

    def intervals(self, i: int, j: int) -> np.ndarray:
        """Dexels of ray (i, j) as an array of shape (m, 2), float64 ``[near, far]`` rows."""
        r = int(i) * self.ny + int(j)
        c = int(self.cnt[r])
        return np.stack([self.near[r, :c], self.far[r, :c]], axis=1).astype(np.float64)

    def to_csr(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Compact lists ``(offsets (n_rays+1,) int64, near (m,) f4, far (m,) f4)``."""
        from . import _csr_kernels

        offsets = np.zeros(self.n_rays + 1, dtype=np.int64)
        np.cumsum(self.cnt, out=offsets[1:])
        near = np.empty(int(offsets[-1]), dtype=np.float32)
        far = np.empty(int(offsets[-1]), dtype=np.float32)
        _csr_kernels.pack(self.near, self.far, self.cnt, offsets, near, far)
        return offsets, near, far

    def top(self) -> np.ndarray:
        """Top surface seen from above: last FarZ of every ray, NaN where empty.

        Returns
        -------
        ndarray of shape (nx, ny), float64, mm
        """
        out = np.empty(self.n_rays, dtype=np.float64)
        _k.top_of(self.near, self.far, self.cnt, out)
        return out.reshape(self.nx, self.ny)

    def same_as(self, other: "DexelWorkpiece") -> bool:
        """True when both hold the same rays and exactly the same dexels."""
        if (self.nx, self.ny, self.x0, self.y0, self.pitch) != (other.nx, other.ny, other.x0, other.y0, other.pitch):
            return False
        a, b = self.to_csr(), other.to_csr()
        return all(np.array_equal(p, q) for p, q in zip(a, b))

    def copy(self) -> "DexelWorkpiece":
        return DexelWorkpiece(self.x0, self.y0, self.pitch, self.nx, self.ny, self.near.copy(),
                              self.far.copy(), self.cnt.copy(), self.created, self.deleted)

    def grow(self, slots: int) -> None:
        """Make room for at least ``slots`` dexels per ray."""
        if slots <= self.slots:
            return
        self.near = _widen(self.near, slots)
        self.far = _widen(self.far, slots)

    def __repr__(self) -> str:
        return (f"DexelWorkpiece(nx={self.nx}, ny={self.ny}, x0={self.x0:g}, y0={self.y0:g}, "
                f"pitch={self.pitch:g}, dexels={self.n_dexels}, created={self.created}, deleted={self.deleted})")

    # ---- cutting ------------------------------------------------------------------------

    def cut(self, xyz: np.ndarray, cutter: Any, tool_slot: np.ndarray | None = None) -> "DexelWorkpiece":
        """Subtract the cutter at each tool-tip position, in order (no history).

        Parameters
        ----------
        xyz : ndarray of shape (n, 3), float64
            Tool-tip positions in mm.
        cutter : Cutter or sequence of Cutter
            One cutter, or a list indexed by ``tool_slot``.
        tool_slot : ndarray of shape (n,), int, optional
            Index into ``cutter`` per position (default all 0).

        Returns
        -------
        DexelWorkpiece
            ``self``, cut in place.
        """
        from .pieces import Pieces

        return self.sweep(Pieces.stamps(xyz), cutter, tool_slot)

    def sweep(self, pieces: Any, cutter: Any, tool_slot: np.ndarray | None = None) -> "DexelWorkpiece":
        """Subtract the exact sweep of the cutter along path pieces, in order (no history).

        Parameters
        ----------
        pieces : zmap.sim.pieces.Pieces
            The pieces of a program's positions (:meth:`zmap.sim.pieces.Pieces.of`).
        cutter : Cutter or sequence of Cutter
            One cutter, or a list indexed by ``tool_slot``.
        tool_slot : ndarray of shape (n,), int, optional
            Index into ``cutter`` per stage (default all 0).

        Returns
        -------
        DexelWorkpiece
            ``self``, cut in place.
        """
        cutters = list(cutter) if isinstance(cutter, (list, tuple)) else [cutter]
        slot = (np.zeros(len(pieces), dtype=np.int32) if tool_slot is None
                else np.ascontiguousarray(tool_slot, dtype=np.int32))
        run_cut(self, pieces, slot, cutter_table(cutters), 0, len(pieces), 0, None)
        return self


def _widen(a: np.ndarray, slots: int) -> np.ndarray:
    out = np.zeros((a.shape[0], slots), dtype=a.dtype)
    out[:, : a.shape[1]] = a
    return out


def _check_pitch(pitch: Any) -> float:
    try:
        p = float(pitch)
    except (TypeError, ValueError):
        raise ValueError(f"pitch must be a positive number of mm, got {pitch!r}") from None
    if not (math.isfinite(p) and p > 0):
        raise ValueError(f"pitch must be a positive number of mm, got {p!r}")
    return p


def run_cut(wp: DexelWorkpiece, pieces: Any, slot: np.ndarray, table: tuple, start: int, stop: int,
            stage0: int, recorder: Any, progress: Any = None, chunk: int = 4096) -> np.ndarray:
    """Cut stages ``start..stop-1`` into ``wp``, growing slots and pools as needed.

    ``pieces`` is a :class:`zmap.sim.pieces.Pieces` (each stage cuts the exact sweep of its
    path piece) or an (n, 3) array of tool tips (each stamps the tool there). ``recorder``
    is a :class:`zmap.sim.history.Recorder` (or None for no history); it owns the per-dexel
    ids and the pools. Returns the kernel's stats vector of this call.
    """
    from .pieces import Pieces

    if not isinstance(pieces, Pieces):
        pieces = Pieces.stamps(pieces)
    code, radius, corner, length = table
    stats = np.zeros(_k.N_STATS, dtype=np.int64)
    if recorder is not None:
        recorder.load_counts(stats)
    p = start
    while p < stop:
        q = min(stop, p + chunk)
        mv, t0, t1 = pieces.params(p, q)
        sl = np.ascontiguousarray(slot[p:q])
        args = recorder.kernel_args() if recorder is not None else _empty_history_args()
        nxt = p + _k.cut_pieces(pieces.kind, pieces.geo, mv, t0, t1, sl, code, radius, corner, length,
                                0, q - p, stage0 + p, wp.x0, wp.y0, wp.pitch, wp.nx, wp.ny, wp.near,
                                wp.far, wp.cnt, *args, stats)
        status = stats[_k.ST_STATUS]
        if status == _k.NEED_SLOTS:
            wp.grow(2 * wp.slots)
            if recorder is not None:
                recorder.grow_slots(wp.slots)
        elif status == _k.NEED_POOL:
            recorder.grow_pools(stats)
        if progress is not None and nxt > p:
            progress.update(nxt - p)
        p = nxt
    wp.created += int(stats[_k.ST_CREATED])
    wp.deleted += int(stats[_k.ST_DELETED])
    if recorder is not None:
        recorder.store_counts(stats)
    return stats
