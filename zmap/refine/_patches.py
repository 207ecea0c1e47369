"""The data of an e-map's cell patches and its storage.

A base cell that missed the exact surface carries a finer EZ-map over an ``m x m`` sub-grid
of its own or a dense lattice (:class:`CellPatchData`; :mod:`zmap.refine.patch` builds
them), and a sub-cell of a patch that still misses a lattice of its own
(:class:`SubLattices`). Here are their data, the helpers that lay out a patch's sub-grid and
sub-edges and code its heights on one scale (:func:`code_patch`), and their storage in the
bit streams of :mod:`zmap.refine._ecodec`. The patches' evaluation is
:class:`zmap.refine._emap.CellPatches`': an EZ patch is evaluated as an
:class:`zmap.refine._emap.EZMap` over its cell's sub-grid, and an e-map stores its patches,
so the data sit below the e-map and the evaluation beside it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Self

import numpy as np

from ..grid import ZMap
from ._ecodec import (
    NAN_CODE,
    _bit_width,
    _narrow,
    _nibbles,
    _pack_bits,
    _pack_steps,
    _segment_cumsum,
    _stored_step,
    _unnibble,
    _unpack_bits,
    _unpack_steps,
    encode_heights,
    pack_codes,
    pack_offsets,
    unpack_codes,
    unpack_offsets,
)
from ._eedges import _n_points, edge_count

__all__ = ["CellPatchData", "SubLattices", "_pack_counts", "_unpack_counts", "all_edges", "code_patch",
           "full_counts", "sub_grid"]


def code_patch(m: int, nodes: np.ndarray, heights: np.ndarray, counts: np.ndarray, quantum: float = 0.0) -> tuple:
    """A level-``m`` patch's data ``(m, nodes, codes, lo, step, counts)`` on one 16-bit scale.

    Its sub-grid ``nodes`` ((m+1, m+1), float64) and e-point ``heights`` ((P,), NaN = none)
    are coded over their common range (:func:`encode_heights`, no finer than ``quantum``); the
    nodes come back decoded
    (what the patch evaluates and stores as codes), ``lo`` and ``step`` repeated per sub-edge.
    """
    nodes = np.asarray(nodes, dtype=np.float64)
    allv = np.concatenate([nodes.ravel(), np.asarray(heights, dtype=np.float64)])
    codes, lo, step = encode_heights(np.array([0, allv.size], dtype=np.int64), allv, quantum)
    dec = np.float64(lo[0]) + np.float64(step[0]) * codes.astype(np.float64)
    dec[codes == NAN_CODE] = np.nan
    S = int(np.asarray(counts).size)
    return (int(m), dec[:nodes.size].reshape(nodes.shape), codes[nodes.size:], np.full(S, lo[0], np.float32),
            np.full(S, step[0], np.float32), np.asarray(counts, dtype=np.uint16))


def full_counts(level, dx: float, dy: float, interval: float) -> np.ndarray:
    """Per sub-edge e-points of patches at ``level`` (ints, ``-n`` a lattice: one 0) on a
    ``dx`` by ``dy`` base when every sub-edge holds all its points (as format 2 stored them)."""
    out = []
    for m in np.asarray(level, dtype=np.int64).ravel():
        if m <= 0:
            out.append(np.zeros(1, dtype=np.uint16))
        else:
            nx_, ny_ = _n_points(dx / m, interval), _n_points(dy / m, interval)
            out.append(np.concatenate([np.full(m * (m + 1), nx_), np.full(m * (m + 1), ny_)]).astype(np.uint16))
    return np.concatenate(out) if out else np.zeros(0, dtype=np.uint16)


def _pack_counts(counts: np.ndarray) -> dict[str, np.ndarray]:
    """Sub-edge counts as stored: a bit per sub-edge (it keeps points: most keep none) and
    the non-zero counts, two to a byte when all are below 16 (``counts_nz``, ``counts4nz``),
    else less one in the bits the largest needs (``countsbnz``, width ``counts_bw``; format 5:
    a byte each, ``counts8nz``); above 255 two bytes each (``counts``). Format 5's first
    commits stored every count two to a byte (``counts4``)."""
    c = np.asarray(counts)
    if c.size and int(c.max()) < 16:
        c = c.astype(np.uint8)
        return {"counts_nz": np.packbits(c > 0), "counts4nz": _nibbles(c[c > 0])}
    if c.size and int(c.max()) < 256:
        # longer sub-edges (level 2 at grid 0.5, finer sub-grids of a coarse base: up to 24
        # points): the non-zero counts minus one in the bits the largest needs (format 6)
        v = c[c > 0].astype(np.int64) - 1
        w = _bit_width(v)
        return {"counts_nz": np.packbits(c > 0), "counts_bw": np.array([w], dtype=np.uint8),
                "countsbnz": _pack_bits(v, w)}
    return {"counts": c.astype(np.uint8 if c.size == 0 or int(c.max()) < 256 else np.uint16)}


def _unpack_counts(a: dict, size: int) -> np.ndarray:
    """Inverse of :func:`_pack_counts`: ``size`` counts, int64."""
    if "counts_nz" in a:
        nz = np.unpackbits(np.asarray(a["counts_nz"], dtype=np.uint8), count=size).astype(bool)
        c = np.zeros(size, dtype=np.int64)
        if "countsbnz" in a:
            v = _unpack_bits(a["countsbnz"], int(nz.sum()), int(np.asarray(a["counts_bw"]).ravel()[0]),
                             "sub-edge counts") + 1
            c[nz] = v
        elif "counts8nz" in a:  # format 5
            v = np.asarray(a["counts8nz"]).astype(np.int64)
            if v.size != int(nz.sum()):
                raise ValueError(f"cell patches: {v.size} sub-edge counts for {int(nz.sum())} sub-edges with points")
            c[nz] = v
        else:
            c[nz] = _unnibble(a["counts4nz"], int(nz.sum()), "sub-edge counts")
        return c
    if "counts4" in a:
        b = np.asarray(a["counts4"], dtype=np.uint8)
        c = np.empty(2 * b.size, dtype=np.int64)
        c[0::2], c[1::2] = b & 15, b >> 4
        if c.size not in (size, size + 1):
            raise ValueError(f"cell patches: {c.size} packed counts for {size} sub-edges")
        return c[:size]
    return np.asarray(a["counts"], dtype=np.int64)


def _segment_sums(values: np.ndarray, off: np.ndarray) -> np.ndarray:
    """Sums of ``values[off[k]:off[k+1]]`` per segment k (0 for an empty one)."""
    c = np.concatenate([[0], np.cumsum(np.asarray(values, dtype=np.int64))])
    return c[off[1:]] - c[off[:-1]]


def sub_grid(base: ZMap, cell: int, m: int, z: np.ndarray | None = None) -> ZMap:
    """The ``m x m`` sub-grid over base cell ``cell`` (base frame); heights ``z`` or zeros."""
    ci, cj = divmod(int(cell), base.ny - 1)
    zz = np.zeros((m + 1, m + 1)) if z is None else z
    return ZMap(base.x0 + ci * base.dx, base.y0 + cj * base.dy, base.dx / m, base.dy / m, zz, base.angle,
                base.origin)


def all_edges(sub: ZMap, interval: float) -> tuple[np.ndarray, np.ndarray]:
    """Edge ids and CSR offsets of an e-map with points on every edge of ``sub``."""
    nx, ny = sub.shape
    E = edge_count(nx, ny)
    ids = np.arange(E, dtype=np.int64)
    counts = np.where(ids < (nx - 1) * ny, _n_points(sub.dx, interval), _n_points(sub.dy, interval))
    offsets = np.zeros(E + 1, dtype=np.int64)
    np.cumsum(counts, out=offsets[1:])
    return ids, offsets


def _patch_chords(level: np.ndarray, node_off: np.ndarray, edge_off: np.ndarray, code_off: np.ndarray,
                  counts: np.ndarray, node_codes: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per code of the EZ patches' sub-edges: its place in the codes, the sub-edge it lies
    on (global index) and the code the chord between the sub-edge's two end nodes gives at
    it (integer arithmetic on the node codes: what :meth:`CellPatchData.to_arrays` stores the
    codes' differences from)."""
    m = np.asarray(level, dtype=np.int64)
    K = m.size
    counts = np.asarray(counts, dtype=np.int64)
    kk = np.repeat(np.arange(K), np.diff(edge_off))
    me = np.maximum(m[kk], 1)
    le = np.arange(kk.size, dtype=np.int64) - edge_off[kk]
    nxe = me * (me + 1)
    isx = le < nxe
    i = np.where(isx, le // (me + 1), (le - nxe) // me)
    j = np.where(isx, le % (me + 1), (le - nxe) % me)
    ia = node_off[kk] + i * (me + 1) + j
    ib = np.where(isx, ia + me + 1, ia + 1)
    ez = m[kk] > 0
    cnt = np.where(ez, counts, 0)
    first = code_off[kk] + _segment_cumsum(cnt, edge_off) - cnt  # each sub-edge's first code
    g = np.repeat(np.arange(kk.size), cnt)
    q = np.arange(g.size, dtype=np.int64) - np.repeat(np.cumsum(cnt) - cnt, cnt) + 1
    nc = np.asarray(node_codes, dtype=np.int64)
    A = nc[ia[g]] if g.size else np.zeros(0, np.int64)
    B = nc[ib[g]] if g.size else np.zeros(0, np.int64)
    c1 = cnt[g] + 1
    pred = A + (2 * (B - A) * q + c1) // (2 * c1)
    return np.repeat(first, cnt) + q - 1, g, pred


def _patch_segments(seg: np.ndarray, nn: np.ndarray, edge_off: np.ndarray, counts: np.ndarray,
                    raw: np.ndarray, level: np.ndarray | None = None) -> np.ndarray:
    """Offsets of the bit stream's segments of the cell patches: a plain patch (``raw``) is
    one (its nodes then its codes), any other its nodes, then each sub-edge that holds codes;
    with ``level`` (format 6) its nodes a row of the sub-grid a segment."""
    total = int(seg[-1])
    start = np.zeros(total + 1, dtype=bool)
    start[seg[:-1]] = True
    if level is not None:
        m = np.asarray(level, dtype=np.int64)
        rows = np.flatnonzero(~np.asarray(raw, dtype=bool) & (m > 0) & (nn > 0))
        if rows.size:
            r = np.repeat(rows, m[rows])  # rows 1..m of each sub-grid
            k = np.arange(r.size) - np.repeat(np.cumsum(m[rows]) - m[rows], m[rows]) + 1
            start[seg[r] + k * (m[r] + 1)] = True
    K = nn.size
    counts = np.asarray(counts, dtype=np.int64)
    kk = np.repeat(np.arange(K), np.diff(edge_off))
    split = ~np.asarray(raw, dtype=bool)[kk] & (counts > 0)
    first = seg[:-1][kk] + nn[kk] + _segment_cumsum(counts, edge_off) - counts
    start[first[split]] = True
    start[total] = True
    return np.flatnonzero(start).astype(np.int64)


@dataclass(eq=False)
class CellPatchData:
    """The data of finer EZ-maps over single base cells, and its storage (levels, lattices and
    storage: see :mod:`zmap.refine.patch`); :class:`zmap.refine._emap.CellPatches` adds their
    EZ patches' evaluation.

    Parameters
    ----------
    cells : ndarray of shape (K,), int64
        Sorted flat ids ``i * (ny - 1) + j`` of the patched base cells.
    level : ndarray of shape (K,), int16
        Sub-cells per base interval ``m`` of each patch (EZ sub-grid), or ``-n`` for a
        dense lattice of ``n`` intervals per side.
    node_off, code_off, edge_off : ndarray of shape (K+1,), int64
        CSR offsets of each patch's sub-grid heights, e-point codes and sub-edges.
    nodes : ndarray, float64
        Sub-grid heights, ``(m+1) x (m+1)`` per EZ patch in C order (NaN = no surface);
        none for a lattice.
    codes : ndarray, uint16
        E-point heights of every sub-edge (e-map coding, see :mod:`zmap.refine.ez`), or
        the ``(n+1) x (n+1)`` lattice heights in C order.
    lo, step : ndarray, float32
        Per sub-edge (one per lattice) offset and quantum of the codes; every sub-edge of a
        patch has the patch's (:func:`code_patch`), and its nodes are on that scale too.
    counts : ndarray, uint16, optional
        E-points kept on each sub-edge (aligned with ``lo``; 0 for a lattice): a smooth
        sub-edge keeps every ``s``-th of its points (:func:`decimate`). Default: all of them.

    Stored (:meth:`to_arrays`, :attr:`nbytes`): cells, level, nodes, codes, lo, step and
    counts; the offsets follow from the levels and counts and are rebuilt on load.
    """

    cells: np.ndarray
    level: np.ndarray
    node_off: np.ndarray
    nodes: np.ndarray
    code_off: np.ndarray
    codes: np.ndarray
    edge_off: np.ndarray
    lo: np.ndarray
    step: np.ndarray
    counts: np.ndarray | None = None
    shared: bool = True
    subs: SubLattices | None = None
    _maps: dict = field(default_factory=dict, repr=False)  # CellPatches' evaluation tables

    def __post_init__(self) -> None:
        self.cells = np.ascontiguousarray(self.cells, dtype=np.int64)
        if self.counts is None:  # lattices only
            self.counts = np.zeros(self.lo.shape, dtype=np.uint16)
        self.level = np.ascontiguousarray(self.level, dtype=np.int16)
        for name in ("node_off", "code_off", "edge_off"):
            setattr(self, name, np.ascontiguousarray(getattr(self, name), dtype=np.int64))
        self.nodes = np.ascontiguousarray(self.nodes, dtype=np.float64)
        self.codes = np.ascontiguousarray(self.codes, dtype=np.uint16)
        self.lo = np.ascontiguousarray(self.lo, dtype=np.float32)
        self.step = np.ascontiguousarray(self.step, dtype=np.float32)
        self.counts = np.ascontiguousarray(self.counts, dtype=np.uint16)
        K = self.cells.shape[0]
        if self.level.shape != (K,) or any(getattr(self, n).shape != (K + 1,)
                                           for n in ("node_off", "code_off", "edge_off")):
            raise ValueError(f"cell patches: level must have shape ({K},) and the offsets ({K + 1},)")
        if K and (np.any(np.diff(self.cells) <= 0) or np.any(self.level == 0)):
            raise ValueError("cell patches: cells must be strictly increasing and levels non-zero")
        m = self.level.astype(np.int64)
        ez, n = m > 0, -m
        if (not np.array_equal(np.diff(self.node_off), np.where(ez, (m + 1) ** 2, 0))
                or self.node_off[-1] != self.nodes.size
                or not np.array_equal(np.diff(self.edge_off), np.where(ez, 2 * m * (m + 1), 1))
                or self.edge_off[-1] != self.lo.size or self.lo.shape != self.step.shape or self.code_off[0] != 0
                or self.code_off[-1] != self.codes.size or np.any(np.diff(self.code_off) < 0)
                or not np.array_equal(np.diff(self.code_off)[~ez], (n[~ez] + 1) ** 2)
                or self.counts.shape != self.lo.shape
                or not np.array_equal(np.diff(self.code_off)[ez], _segment_sums(self.counts, self.edge_off)[ez])):
            raise ValueError("cell patches: offsets do not match the levels, counts and array sizes")
        ke = np.repeat(np.arange(K), np.diff(self.edge_off))
        if self.shared and K and (np.any(self.lo != self.lo[self.edge_off[:-1]][ke])
                                  or np.any(self.step != self.step[self.edge_off[:-1]][ke])):
            raise ValueError("cell patches: the sub-edges of a patch must share its lo and step (code_patch)")

    @classmethod
    def empty(cls) -> Self:
        z = np.zeros(0)
        zero = np.zeros(1, dtype=np.int64)
        return cls(np.zeros(0, np.int64), np.zeros(0, np.int16), zero, z, zero, np.zeros(0, np.uint16), zero,
                   np.zeros(0, np.float32), np.zeros(0, np.float32), np.zeros(0, np.uint16))

    @classmethod
    def pack(cls, per_cell: dict[int, tuple]) -> Self:
        """Patches from ``{cell: (m, nodes, codes, lo, step, counts)}`` (a lattice's counts
        may be left out)."""
        if not per_cell:
            return cls.empty()
        keys = sorted(per_cell)
        parts = [per_cell[k] for k in keys]
        off = lambda sizes: np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        return cls(np.array(keys, dtype=np.int64), np.array([p[0] for p in parts], dtype=np.int16),
                   off([p[1].size for p in parts]), np.concatenate([p[1].ravel() for p in parts]),
                   off([p[2].size for p in parts]), np.concatenate([p[2] for p in parts]),
                   off([p[3].size for p in parts]), np.concatenate([p[3] for p in parts]),
                   np.concatenate([p[4] for p in parts]),
                   np.concatenate([p[5] if len(p) > 5 else np.zeros(p[3].size, np.uint16)
                                   for p in parts]).astype(np.uint16))

    def unpack(self) -> dict[int, tuple]:
        """Inverse of :meth:`pack`."""
        return {int(c): (int(self.level[k]),
                         self.nodes[self.node_off[k]:self.node_off[k + 1]].reshape(max(int(self.level[k]) + 1, 0), -1),
                         self.codes[self.code_off[k]:self.code_off[k + 1]],
                         self.lo[self.edge_off[k]:self.edge_off[k + 1]],
                         self.step[self.edge_off[k]:self.edge_off[k + 1]],
                         self.counts[self.edge_off[k]:self.edge_off[k + 1]]) for k, c in enumerate(self.cells)}

    @property
    def n_patches(self) -> int:
        return int(self.cells.shape[0])

    @property
    def nbytes(self) -> int:
        """Bytes stored (:meth:`to_arrays`: cells, level, nodes, codes, lo, step, counts)."""
        return int(sum(a.nbytes for a in self.to_arrays().values()))

    def to_arrays(self) -> dict[str, np.ndarray]:
        """Stored arrays: cells, level, the sub-grid nodes as 16-bit codes on their patch's
        scale, the e-point/lattice codes, one lo and step per patch, the sub-edge counts, and
        the sub-lattices (``sub_*``, :class:`SubLattices`)."""
        first = self.edge_off[:-1]
        lo, step = self.lo[first], self.step[first]
        k = np.repeat(np.arange(self.n_patches), np.diff(self.node_off))
        lo_n, st_n = lo[k].astype(np.float64), step[k].astype(np.float64)
        with np.errstate(invalid="ignore", divide="ignore"):
            q = np.where(st_n > 0, np.rint((self.nodes - lo_n) / np.where(st_n > 0, st_n, 1.0)), 0.0)
        node_codes = np.clip(np.nan_to_num(q, nan=0.0), 0, NAN_CODE - 1).astype(np.uint16)
        node_codes[np.isnan(self.nodes)] = NAN_CODE
        subs = {f"sub_{k}": v for k, v in self.subs.to_arrays().items()} if self.subs is not None else {}
        # a patch's node codes and its codes, on its one scale, in the bit stream; an EZ patch
        # with heights everywhere stores each sub-edge's codes as their (zigzag) differences
        # from the chord between its end nodes, a segment each (see _patch_segments)
        nn, nc = np.diff(self.node_off), np.diff(self.code_off)
        seg = np.concatenate([[0], np.cumsum(nn + nc)]).astype(np.int64)
        allc = np.empty(int(seg[-1]), dtype=np.int64)
        at_node = np.repeat(seg[:-1] - self.node_off[:-1], nn) + np.arange(node_codes.size)
        at_code = np.repeat(seg[:-1] + nn - self.code_off[:-1], nc) + np.arange(self.codes.size)
        allc[at_node] = node_codes
        allc[at_code] = self.codes
        K = self.n_patches
        raw = self.level <= 0
        if K:
            nan_p = np.zeros(K, dtype=bool)
            ne = np.flatnonzero(nn + nc > 0)
            nan_p[ne] = np.logical_or.reduceat(allc == NAN_CODE, seg[:-1][ne])
            raw |= nan_p
            where, g, pred = _patch_chords(self.level, self.node_off, self.edge_off, self.code_off, self.counts,
                                           node_codes)
            # the difference modulo 2**16, as a signed 16-bit value, zigzagged (a wall's sub-edge:
            # up to 16 bits, as plain)
            r = (self.codes[where].astype(np.int64) - pred + 32768) % 65536 - 32768
            zz = np.where(r >= 0, 2 * r, -2 * r - 1)
            kk = np.repeat(np.arange(K), np.diff(self.edge_off))[g]
            use = ~raw[kk]
            allc[at_code[where[use]]] = zz[use]
        packed = {f"codes_{k}": v for k, v in pack_codes(allc.astype(np.uint16),
                                                         _patch_segments(seg, nn, self.edge_off, self.counts,
                                                                         raw, self.level)).items()}
        level = self.level.astype(np.int8) if K == 0 or int(np.abs(self.level).max()) < 128 else self.level
        # format 6: the cells as the bits of their gaps, the quanta as the e-map's (one common
        # value behind a bit each), the sub-grid nodes a row a segment (``node_rows``)
        if K == 0:
            cells = {"cells": _narrow(self.cells)}
        else:
            gaps = np.diff(np.concatenate([[0], self.cells]))
            w = _bit_width(gaps)
            cells = {"cells_w": np.array([w], dtype=np.uint8), "cells_gaps": _pack_bits(gaps, w),
                     "node_rows": np.ones(1, dtype=np.uint8)}
        return (cells | {"level": level, "lo": lo, "codes_raw": np.packbits(raw)} | _pack_steps(step) | packed
                | _pack_counts(self.counts) | subs)

    @classmethod
    def from_arrays(cls, a: dict[str, np.ndarray], grid: tuple[float, float, float] | None = None) -> Self:
        """Inverse of :meth:`to_arrays`; also reads format 2's arrays (offsets, no counts: every
        sub-edge full), given ``grid = (dx, dy, interval)`` of the e-map."""
        if "counts" not in a and "counts4" not in a and "counts_nz" not in a:
            # format 2: float64 nodes and a scale per sub-edge, every sub-edge full; re-coded
            # on one scale per patch (heights move by at most half the patch's quantum)
            if grid is None:
                raise ValueError("cell patches without counts (format 2) need the e-map's (dx, dy, interval)")
            old = cls(a["cells"], a["level"], a["node_off"], a["nodes"], a["code_off"], a["codes"], a["edge_off"],
                      a["lo"], a["step"], full_counts(a["level"], *grid), shared=False)
            per = {}
            for c, (m_, nodes, codes, lo, step, counts) in old.unpack().items():
                if m_ < 0:
                    per[c] = (m_, nodes, codes, lo, step, counts)
                    continue
                e = np.repeat(np.arange(lo.size), counts.astype(np.int64))
                h = lo[e].astype(np.float64) + step[e].astype(np.float64) * codes
                h[codes == NAN_CODE] = np.nan
                per[c] = code_patch(m_, nodes, h, counts)
            return cls.pack(per)
        m = np.asarray(a["level"], dtype=np.int64)
        off = lambda sizes: np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        ez = m > 0
        edge_off = off(np.where(ez, 2 * m * (m + 1), 1))
        counts = _unpack_counts(a, int(edge_off[-1]))
        if edge_off[-1] != counts.size:
            raise ValueError(f"cell patches: {counts.size} counts for the {edge_off[-1]} sub-edges of the levels")
        K = m.size
        lo_p, st_p = np.asarray(a["lo"], dtype=np.float32), _unpack_steps(a, K)
        if "cells_gaps" in a:  # format 6
            cells = np.cumsum(_unpack_bits(a["cells_gaps"], K, int(np.asarray(a["cells_w"]).ravel()[0]), "cells"))
        else:
            cells = np.asarray(a["cells"], dtype=np.int64)
        node_off = off(np.where(ez, (m + 1) ** 2, 0))
        code_off = off(np.where(ez, _segment_sums(counts, edge_off), (1 - m) ** 2))
        if "codes_bits" in a:
            nn, ncs = np.diff(node_off), np.diff(code_off)
            seg = off(nn + ncs)
            raw = (np.unpackbits(np.asarray(a["codes_raw"], dtype=np.uint8), count=K).astype(bool)
                   if "codes_raw" in a else np.ones(K, dtype=bool))
            allc = unpack_codes(a["codes_bits"], a["codes_w4"],
                                _patch_segments(seg, nn, edge_off, counts, raw, m if "node_rows" in a else None),
                                a.get("codes_mode"), a.get("codes_r4"))
            nc = allc[np.repeat(seg[:-1] - node_off[:-1], nn) + np.arange(int(node_off[-1]))]
            codes = allc[np.repeat(seg[:-1] + nn - code_off[:-1], ncs) + np.arange(int(code_off[-1]))].astype(np.int64)
            if not raw.all():
                where, g, pred = _patch_chords(m, node_off, edge_off, code_off, counts, nc)
                kk = np.repeat(np.arange(K), np.diff(edge_off))[g]
                use = ~raw[kk]
                zz = codes[where[use]]
                codes[where[use]] = (pred[use] + ((zz >> 1) ^ -(zz & 1))) % 65536
                d = codes[where[use]]
                if np.any((d < 0) | (d >= NAN_CODE)):
                    raise ValueError("cell patches: a sub-edge's decoded codes are out of range")
            codes = codes.astype(np.uint16)
        else:
            nc, codes = np.asarray(a["node_codes"], dtype=np.uint16), a["codes"]
        if lo_p.shape != (K,) or st_p.shape != (K,) or nc.size != node_off[-1]:
            raise ValueError(f"cell patches: lo, step must hold one value per patch ({K}) and the node codes "
                             f"{node_off[-1]}, got {lo_p.size}, {st_p.size}, {nc.size}")
        kn = np.repeat(np.arange(K), np.diff(node_off))
        nodes = lo_p[kn].astype(np.float64) + st_p[kn].astype(np.float64) * nc
        nodes[nc == NAN_CODE] = np.nan
        ke = np.repeat(np.arange(K), np.diff(edge_off))
        subs = SubLattices.from_arrays({k[4:]: v for k, v in a.items() if k.startswith("sub_")}) if any(
            k.startswith("sub_") for k in a) else None
        return cls(cells, a["level"], node_off, nodes, code_off, codes, edge_off, lo_p[ke], st_p[ke],
                   counts, subs=subs)

    def _lattice(self, k: np.ndarray, base: ZMap, lx: np.ndarray, ly: np.ndarray) -> np.ndarray:
        """Bilinear heights in lattice patches ``k`` (one per point) at local xy; NaN on a
        missing corner."""
        n = -self.level[k].astype(np.int64)
        ci, cj = np.divmod(self.cells[k], base.ny - 1)
        u = np.clip((lx - base.x0 - ci * base.dx) / base.dx * n, 0.0, n)
        v = np.clip((ly - base.y0 - cj * base.dy) / base.dy * n, 0.0, n)
        i = np.minimum(u.astype(np.int64), n - 1)
        j = np.minimum(v.astype(np.int64), n - 1)
        fu, fv = u - i, v - j
        at = self.code_off[k] + i * (n + 1) + j
        lo = self.lo[self.edge_off[k]].astype(np.float64)
        st = self.step[self.edge_off[k]].astype(np.float64)

        def z(q):
            cq = self.codes[q]
            return np.where(cq == NAN_CODE, np.nan, lo + st * cq.astype(np.float64))

        return ((1 - fu) * ((1 - fv) * z(at) + fv * z(at + 1))
                + fu * ((1 - fv) * z(at + n + 1) + fv * z(at + n + 2)))


@dataclass(eq=False)
class SubLattices:
    """Dense lattices over single sub-cells of level-``m`` cell patches (the last resort, where
    a patch misses in a few of its sub-cells: see :mod:`zmap.refine.patch`).

    Parameters
    ----------
    mn : ndarray of shape (2,), int64
        ``(m, n)``: sub-cells per base interval of the patches they sit in, and lattice
        intervals per side of a sub-cell (its diagonal over ``n`` is at most the tolerance).
    keys : ndarray of shape (S,), int64
        Sorted ``cell * m * m + si * m + sj``: base cell and sub-cell (``si`` along x).
    codes : ndarray of shape (S * (n+1)**2,), uint16
        Lattice heights, C order per sub-cell, :data:`NAN_CODE` = none.
    lo, step : ndarray of shape (S,), float32
        Offset and quantum of each sub-lattice's codes.
    quantum : float
        The finest quantum they were coded at (:func:`encode_heights`; 0: unknown), which
        lets :meth:`to_arrays` store the offsets as lattice steps (:func:`pack_offsets`).
    """

    mn: np.ndarray
    keys: np.ndarray
    codes: np.ndarray
    lo: np.ndarray
    step: np.ndarray
    quantum: float = 0.0

    def __post_init__(self) -> None:
        self.mn = np.asarray(self.mn, dtype=np.int64).ravel()
        self.keys = np.ascontiguousarray(self.keys, dtype=np.int64)
        self.codes = np.ascontiguousarray(self.codes, dtype=np.uint16)
        self.lo = np.ascontiguousarray(self.lo, dtype=np.float32)
        self.step = np.ascontiguousarray(self.step, dtype=np.float32)
        S = self.keys.shape[0]
        if (self.mn.shape != (2,) or self.mn.min() < 1 or self.lo.shape != (S,) or self.step.shape != (S,)
                or self.codes.size != S * (self.mn[1] + 1) ** 2 or (S and np.any(np.diff(self.keys) <= 0))):
            raise ValueError(f"sub-lattices: (m, n) = {self.mn.tolist()}, {S} increasing keys, one lo/step each and "
                             f"(n+1)^2 codes each expected, got {self.lo.size}, {self.step.size}, {self.codes.size}")

    @property
    def n(self) -> int:
        return int(self.keys.shape[0])

    def to_arrays(self) -> dict[str, np.ndarray]:
        """Stored arrays: each lattice row's codes a segment of :func:`pack_codes` (format 6,
        ``rows``; a row across a wall needs wide codes, the others few bits: on the Ventilator
        43 KB against 58 KB a lattice a segment), the offsets on the quantum's lattice."""
        seg = np.arange(self.n * (int(self.mn[1]) + 1) + 1, dtype=np.int64) * (int(self.mn[1]) + 1)
        return {"mn": self.mn, "keys": _narrow(self.keys), "step": _stored_step(self.step),
                "rows": np.ones(1, dtype=np.uint8)} | pack_offsets(self.lo, self.quantum) | {
            f"codes_{k}": v for k, v in pack_codes(self.codes, seg).items()}

    @classmethod
    def from_arrays(cls, a: dict[str, np.ndarray]) -> SubLattices:
        if "codes_bits" in a:
            mn = np.asarray(a["mn"], dtype=np.int64).ravel()
            S, n1 = np.asarray(a["keys"]).size, int(mn[1]) + 1
            seg = (np.arange(S * n1 + 1, dtype=np.int64) * n1 if "rows" in a  # format 6: a row a segment
                   else np.arange(S + 1, dtype=np.int64) * n1 * n1)
            codes = unpack_codes(a["codes_bits"], a["codes_w4"], seg, a.get("codes_mode"), a.get("codes_r4"))
        else:
            codes = a["codes"]
        quantum = float(np.asarray(a["lo_lattice"]).ravel()[1]) if "lo_lattice" in a else 0.0
        return cls(a["mn"], a["keys"], codes, unpack_offsets(a, np.asarray(a["keys"]).size), a["step"], quantum)

    def override(self, cell: np.ndarray, base: ZMap, lx: np.ndarray, ly: np.ndarray, h: np.ndarray) -> np.ndarray:
        """``h`` with the points in a sub-lattice (base ``cell`` ids, local xy) answered by it."""
        m, n = int(self.mn[0]), int(self.mn[1])
        ci, cj = np.divmod(cell, base.ny - 1)
        fu = np.clip((lx - base.x0 - ci * base.dx) / base.dx * m, 0.0, m)
        fv = np.clip((ly - base.y0 - cj * base.dy) / base.dy * m, 0.0, m)
        si = np.minimum(fu.astype(np.int64), m - 1)
        sj = np.minimum(fv.astype(np.int64), m - 1)
        key = cell * m * m + si * m + sj
        pos = np.minimum(np.searchsorted(self.keys, key), self.n - 1)
        hit = np.flatnonzero(self.keys[pos] == key)
        if hit.size == 0:
            return h
        k = pos[hit]
        u = np.clip((fu[hit] - si[hit]) * n, 0.0, n)
        v = np.clip((fv[hit] - sj[hit]) * n, 0.0, n)
        i = np.minimum(u.astype(np.int64), n - 1)
        j = np.minimum(v.astype(np.int64), n - 1)
        a, b = u - i, v - j
        at = k * (n + 1) ** 2 + i * (n + 1) + j
        lo, st = self.lo[k].astype(np.float64), self.step[k].astype(np.float64)

        def z(q):
            cq = self.codes[q]
            return np.where(cq == NAN_CODE, np.nan, lo + st * cq.astype(np.float64))

        h = h.copy()
        h[hit] = ((1 - a) * ((1 - b) * z(at) + b * z(at + 1)) + a * ((1 - b) * z(at + n + 1) + b * z(at + n + 2)))
        return h
