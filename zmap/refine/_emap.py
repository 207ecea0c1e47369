"""The e-map data: :class:`EZMap` and its :class:`CellPatches`, stored and evaluated.

An EZ-map holds e-points on grid edges of a base z-map as 16-bit codes and evaluates its
cells as Coons patches split along walls and sharp edges (paper 004 §3.2, see
:mod:`zmap.refine.ez`); the cells that missed the exact surface carry a finer EZ-map of
their own or a dense lattice (:class:`CellPatches`, see :mod:`zmap.refine.patch`). The two
types hold each other, so they live here together; the procedures that build them are
:func:`zmap.refine.ez.build_ez` and :func:`zmap.refine.patch.patch_failing`, which import
this module (and ``ez`` imports ``patch``: no cycle). Public names are re-exported from
``zmap.refine.ez`` and ``zmap.refine.patch``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..grid import ZMap

__all__ = ["BREAK_RATIO", "FORMAT_VERSION", "QUANTUM_SHARE", "WINDOW_HALF", "NAN_CODE", "SERIAL_BELOW", "CellPatches", "EZMap", "all_edges",
           "SubLattices", "break_thresholds", "code_patch", "decimate", "full_counts",
           "cells_around", "edge_count", "encode_heights", "pack_codes", "sub_grid", "unpack_codes"]

FORMAT_VERSION = 6
#: A windowed edge's break may move this share of an e-map interval from the full
#: sequence's (a kink placed from coded heights: 0.05 of 0.01 mm is 5e-4 mm).
KINK_SHIFT = 0.05
#: Tries at more knots for a thinned edge whose knots show a break (:func:`decimate`).
THIN_ROUNDS = 4
#: A windowed wall edge keeps its full samples from this many before the jump's interval
#: to this many after it (the jump and the slopes its two sides are extended by).
WINDOW_HALF = 1
#: Batches smaller than this are evaluated on one thread (no thread-pool wake-up).
SERIAL_BELOW = 4096
#: A jump or kink must stand out this many times from its neighbours to count as a break.
BREAK_RATIO = 4.0
#: The finest quantum of the coded heights, as a share of the tolerance (:func:`encode_heights`'s
#: ``quantum``): tol/32 = 3.1e-4 mm at tol 0.01 (an error of at most 1.6e-4 mm), about the
#: quantum of a 20 mm wall's 16-bit codes (the paper's Table 2 codes), so no height is coded
#: finer than it needs; stored, an edge's codes take the bits their range needs at that
#: quantum (:func:`pack_codes`), and its offset is a whole number of quanta
#: (:func:`pack_offsets`). Every cell is checked against the exact surface as coded.
QUANTUM_SHARE = 1.0 / 32.0


def edge_count(nx: int, ny: int) -> int:
    """Number of grid edges of an ``nx`` by ``ny`` grid: ``(nx-1)*ny + nx*(ny-1)``."""
    return (nx - 1) * ny + nx * (ny - 1)


#: 16-bit code of an e-point with no height; valid codes are 0 .. NAN_CODE - 1.
NAN_CODE = 65535


def encode_heights(offsets: np.ndarray, heights: np.ndarray, quantum: float = 0.0
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """16-bit codes of e-point heights, per edge ``height = lo + step * code``.

    Parameters
    ----------
    offsets : ndarray of shape (E+1,), int64
        CSR offsets of the edges (each edge owns at least one point).
    heights : ndarray of shape (P,), float64
        Heights in mm, NaN = none.
    quantum : float
        Smallest step, mm (0: none): an edge whose range over ``NAN_CODE - 1`` steps is
        finer codes at this step, so its codes stay below ``range / quantum`` and are
        stored in fewer bits (:func:`pack_codes`); the error is at most ``quantum / 2``.

    Returns
    -------
    codes : ndarray of shape (P,), uint16
        ``round((height - lo) / step)``, :data:`NAN_CODE` for NaN.
    lo, step : ndarray of shape (E,), float32
        The edge's lowest height and its range over ``NAN_CODE - 1`` steps (no finer than
        ``quantum``).

    Examples
    --------
    >>> c, lo, st = encode_heights(np.array([0, 3]), np.array([1.0, np.nan, 3.0]))
    >>> c[:2].tolist(), lo.tolist(), round(float(lo[0] + st[0] * c[2]), 4)
    ([0, 65535], [1.0], 3.0)
    """
    E = offsets.shape[0] - 1
    if E == 0:
        return np.zeros(0, np.uint16), np.zeros(0, np.float32), np.zeros(0, np.float32)
    P = heights.shape[0]
    empty = np.diff(offsets) == 0
    starts = np.minimum(offsets[:-1], max(P - 1, 0))
    finite = ~np.isnan(heights)
    if P == 0:
        lo, hi = np.full(E, np.inf), np.full(E, -np.inf)
    else:
        lo = np.minimum.reduceat(np.where(finite, heights, np.inf), starts)
        hi = np.maximum.reduceat(np.where(finite, heights, -np.inf), starts)
    lo[empty], hi[empty] = np.inf, -np.inf  # reduceat gives an empty segment its next value
    none = ~np.isfinite(lo)
    if quantum > 0 and not none.all():
        # offsets on one lattice, origin + k * quantum (k >= 0), each at or below its edge's
        # lowest height: stored as the integers k in the bits their range needs
        # (:func:`pack_offsets`), not as float32
        lo[none] = hi[none] = np.min(lo[~none])
        lo32 = _lattice_offsets(lo, float(quantum))
    else:
        lo[none] = 0.0
        hi[none] = 0.0
        lo32 = lo.astype(np.float32)
    span = np.maximum(hi - lo32.astype(np.float64), 0.0)
    step32 = half_step(np.maximum(span / (NAN_CODE - 1), float(quantum)))
    e = np.repeat(np.arange(E), np.diff(offsets))
    st = step32[e].astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        q = np.where(st > 0, np.rint((heights - lo32[e].astype(np.float64)) / np.where(st > 0, st, 1.0)), 0.0)
    q = np.clip(np.nan_to_num(q, nan=0.0), 0, NAN_CODE - 1)
    codes = q.astype(np.uint16)
    codes[~finite] = NAN_CODE
    return codes, lo32, step32


def _nibbles(v: np.ndarray) -> np.ndarray:
    """Values 0..15, two to a byte."""
    v = np.asarray(v, dtype=np.uint8)
    if v.size % 2:
        v = np.concatenate([v, np.zeros(1, np.uint8)])
    return (v[0::2] | (v[1::2] << 4)).astype(np.uint8)


def _unnibble(b: np.ndarray, count: int, what: str) -> np.ndarray:
    """Inverse of :func:`_nibbles`: ``count`` values, int64."""
    b = np.asarray(b, dtype=np.uint8)
    v = np.empty(2 * b.size, dtype=np.int64)
    v[0::2], v[1::2] = b & 15, b >> 4
    if v.size not in (count, count + 1):
        raise ValueError(f"e-map arrays: {v.size} {what} for {count} segments")
    return v[:count]


def _segment_cumsum(x: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Running sums of ``x`` restarted at each segment ``offsets[k]:offsets[k+1]``."""
    cs = np.cumsum(x)
    size = np.diff(offsets)
    st = offsets[:-1][size > 0]
    return cs - np.repeat(cs[st] - x[st], size[size > 0])


def _lattice_origin(lowest: float) -> float:
    """The largest float32 value at or below ``lowest``, as float64."""
    o = np.float32(lowest)
    if float(o) > lowest:
        o = np.nextafter(o, np.float32(-np.inf))
    return float(o)


def _lattice_offsets(lo: np.ndarray, quantum: float) -> np.ndarray:
    """float32 offsets ``float32(origin + k * quantum)`` at or below ``lo`` (float64), with
    ``origin`` the float32 at or below ``lo.min()`` (so the lowest edge has ``k = 0``)."""
    origin = _lattice_origin(float(lo.min()))
    k = np.floor((lo - origin) / quantum)
    out = (origin + k * quantum).astype(np.float32)
    for _ in range(4):  # float32 rounding may land just above the edge's lowest height
        up = out.astype(np.float64) > lo
        if not up.any():
            break
        k[up] -= 1.0
        out[up] = (origin + k[up] * quantum).astype(np.float32)
    return out


def _bit_width(v: np.ndarray) -> int:
    """Bits that hold the largest of the non-negative integers ``v`` (at least 1)."""
    return max(1, int(np.max(v)).bit_length()) if np.size(v) else 1


def _pack_bits(v: np.ndarray, w: int) -> np.ndarray:
    """Non-negative integers below ``2**w`` in ``w`` bits each, MSB first, packed."""
    v = np.asarray(v, dtype=np.int64)
    bits = (v[:, None] >> np.arange(w - 1, -1, -1, dtype=np.int64)[None, :]) & 1
    return np.packbits(bits.astype(np.uint8).ravel())


def _unpack_bits(b: np.ndarray, count: int, w: int, what: str) -> np.ndarray:
    """Inverse of :func:`_pack_bits`: ``count`` values, int64."""
    bits = np.unpackbits(np.asarray(b, dtype=np.uint8))
    if not 1 <= w <= 62 or bits.size < count * w or bits.size >= count * w + 8:
        raise ValueError(f"e-map arrays: {bits.size} bits of {what} for {count} values of {w} bits")
    return bits[:count * w].reshape(count, w).astype(np.int64) @ (1 << np.arange(w - 1, -1, -1, dtype=np.int64))


def pack_offsets(lo: np.ndarray, quantum: float) -> dict[str, np.ndarray]:
    """Per-edge offsets as stored: where every one is ``float32(origin + k * quantum)`` with
    ``origin = lo.min()`` and integers ``k >= 0`` (as :func:`encode_heights` places them), the
    ``k`` in the fewest bits that hold them (``lo_k``, MSB first; ``lo_lattice`` holds origin,
    quantum and the width), else the float32 values (``lo``)."""
    lo = np.asarray(lo, dtype=np.float32)
    if lo.size < 8 or not quantum > 0:
        return {"lo": lo}
    origin = float(lo.min())
    k = np.rint((lo.astype(np.float64) - origin) / quantum)
    if k.max() >= 2.0 ** 31 or not np.array_equal((origin + k * quantum).astype(np.float32), lo):
        return {"lo": lo}
    k = k.astype(np.int64)
    w = _bit_width(k)
    return {"lo_lattice": np.array([origin, quantum, w], dtype=np.float64), "lo_k": _pack_bits(k, w)}


def unpack_offsets(arrays: dict, count: int) -> np.ndarray:
    """Inverse of :func:`pack_offsets`: ``count`` float32 offsets."""
    if "lo_k" not in arrays:
        lo = np.asarray(arrays["lo"], dtype=np.float32)
        if lo.shape != (count,):
            raise ValueError(f"e-map arrays: {lo.size} offsets for {count} segments")
        return lo
    origin, quantum, w = (float(v) for v in np.asarray(arrays["lo_lattice"], dtype=np.float64).ravel())
    k = _unpack_bits(arrays["lo_k"], count, int(w), "offsets")
    return (origin + k * quantum).astype(np.float32)


def pack_codes(codes: np.ndarray, offsets: np.ndarray) -> dict[str, np.ndarray]:
    """16-bit codes as stored (format 5), segment by segment (``offsets[k]:offsets[k+1]``: an
    edge, a patch, a lattice), in one bit stream (``bits``, MSB first).

    A segment is stored plainly, each code in the fewest bits ``w`` (1..16) that hold its
    largest code plus one (:data:`NAN_CODE` written as ``2**w - 1``), or, where that takes
    fewer bits and it has no :data:`NAN_CODE`, as its first two codes (``w`` bits each) and
    the second differences of the rest (zigzag, ``rw`` bits each: a smooth run of heights
    differs little from the line through the two before). ``w4`` holds ``w - 1`` per
    segment and ``r4`` ``rw - 1`` per differenced segment (two to a byte), ``mode`` a bit
    per segment. :func:`unpack_codes` restores the codes exactly."""
    codes = np.asarray(codes, dtype=np.uint16)
    offsets = np.asarray(offsets, dtype=np.int64)
    S = offsets.shape[0] - 1
    size = np.diff(offsets)
    P = codes.shape[0]
    nan = codes == NAN_CODE
    c = codes.astype(np.int64)
    v = np.where(nan, 0, c)
    top = np.zeros(S, dtype=np.int64)
    ne = np.flatnonzero(size > 0)
    if ne.size:
        top[ne] = np.maximum.reduceat(v, offsets[:-1][ne])
    w = np.clip(np.ceil(np.log2(top + 2.0)).astype(np.int64), 1, 16)
    seg = np.repeat(np.arange(S), size)
    pos = np.arange(P, dtype=np.int64) - np.repeat(offsets[:-1], size)
    # second differences from the third code of a segment on, zigzagged
    r = np.zeros(P, dtype=np.int64)
    if P > 2:
        r[2:] = c[2:] - 2 * c[1:-1] + c[:-2]
    r = np.where(pos >= 2, r, 0)
    zr = np.where(r >= 0, 2 * r, -2 * r - 1)
    rtop = np.zeros(S, dtype=np.int64)
    if ne.size:
        rtop[ne] = np.maximum.reduceat(zr, offsets[:-1][ne])
    has_nan = np.zeros(S, dtype=bool)
    if ne.size:
        has_nan[ne] = np.logical_or.reduceat(nan, offsets[:-1][ne])
    rw = np.clip(np.ceil(np.log2(rtop + 1.0)).astype(np.int64), 1, 17)
    mode = (~has_nan & (size >= 3) & (rw <= 16)
            & (np.minimum(size, 2) * w + (size - 2) * rw + 4 < size * w))
    dcode = mode[seg] & (pos >= 2)
    wc = np.where(dcode, rw[seg], w[seg])
    val = np.where(dcode, zr, np.where(nan, (1 << wc) - 1, v))
    start = np.concatenate([[0], np.cumsum(wc)])
    b = np.arange(int(start[-1]), dtype=np.int64) - np.repeat(start[:-1], wc)
    bits = (np.repeat(val, wc) >> (np.repeat(wc, wc) - 1 - b)) & 1
    return {"bits": np.packbits(bits.astype(np.uint8)), "w4": _nibbles(w - 1), "mode": np.packbits(mode),
            "r4": _nibbles(rw[mode] - 1)}


def unpack_codes(bits: np.ndarray, w4: np.ndarray, offsets: np.ndarray, mode: np.ndarray | None = None,
                 r4: np.ndarray | None = None) -> np.ndarray:
    """Inverse of :func:`pack_codes` given the segments' ``offsets``: uint16 codes (``mode``
    None: every segment plain)."""
    offsets = np.asarray(offsets, dtype=np.int64)
    S = offsets.shape[0] - 1
    size = np.diff(offsets)
    P = int(offsets[-1])
    w = _unnibble(w4, S, "code widths") + 1
    md = (np.zeros(S, dtype=bool) if mode is None
          else np.unpackbits(np.asarray(mode, dtype=np.uint8), count=S).astype(bool))
    rw = np.zeros(S, dtype=np.int64)
    rw[md] = _unnibble(r4 if r4 is not None else np.zeros(0, np.uint8), int(md.sum()), "difference widths") + 1
    seg = np.repeat(np.arange(S), size)
    pos = np.arange(P, dtype=np.int64) - np.repeat(offsets[:-1], size)
    dcode = md[seg] & (pos >= 2)
    wc = np.where(dcode, rw[seg], w[seg])
    start = np.concatenate([[0], np.cumsum(wc)])
    total = int(start[-1])
    bits = np.asarray(bits, dtype=np.uint8)
    if bits.size != (total + 7) // 8:
        raise ValueError(f"e-map arrays: {bits.size} bytes of codes, {(total + 7) // 8} expected")
    if P == 0:
        return np.zeros(0, dtype=np.uint16)
    bb = np.unpackbits(bits, count=total).astype(np.int64)
    b = np.arange(total, dtype=np.int64) - np.repeat(start[:-1], wc)
    v = np.add.reduceat(bb << (np.repeat(wc, wc) - 1 - b), start[:-1])  # every code has >= 1 bit
    out = np.where(v == (1 << wc) - 1, NAN_CODE, v)
    if md.any():
        # differenced segments: c[q] = 2 c[q-1] - c[q-2] + r[q], as running sums
        r = np.where(dcode, (v >> 1) ^ -(v & 1), 0)
        ne = np.flatnonzero(size > 0)
        c0s, c1s = np.zeros(S, dtype=np.int64), np.zeros(S, dtype=np.int64)
        c0s[ne] = np.add.reduceat(np.where(pos == 0, v, 0), offsets[:-1][ne])
        c1s[ne] = np.add.reduceat(np.where(pos == 1, v, 0), offsets[:-1][ne])
        c0 = c0s[seg]
        d = c1s[seg] - c0  # c1 - c0
        dd = d + _segment_cumsum(r, offsets)  # c[q] - c[q-1] for q >= 2 (and q = 1)
        c = c0 + _segment_cumsum(np.where(pos >= 1, dd, 0), offsets)
        out = np.where(md[seg], c, out)
    if np.any((out < 0) | (out > NAN_CODE)):
        raise ValueError("e-map arrays: decoded codes out of range")
    return out.astype(np.uint16)


def half_step(step: np.ndarray) -> np.ndarray:
    """``step`` rounded up to the nearest float16 value, as float32: a quantum that is
    stored in two bytes (:func:`_stored_step`) and still spans the range over the codes;
    the quantisation error grows by at most 1/1024 of itself (about 6e-8 mm where the
    quantum is below float16's smallest)."""
    step = np.asarray(step, dtype=np.float64)
    h = step.astype(np.float16)
    up = (h.astype(np.float64) < step) & np.isfinite(h)
    h[up] = np.nextafter(h[up], np.float16(np.inf))
    big = ~np.isfinite(h)  # beyond float16 (a range over 4e9 mm): kept as float32
    out = h.astype(np.float32)
    out[big] = step[big].astype(np.float32)
    return out


def _stored_step(step: np.ndarray) -> np.ndarray:
    """Quanta as stored: float16 where that is exact (:func:`half_step`), else float32."""
    h = step.astype(np.float16)
    return h if np.array_equal(h.astype(np.float32), step) else step


def _narrow(ids: np.ndarray) -> np.ndarray:
    """Non-negative ids as stored: uint32 where they fit (the loaders widen them to int64)."""
    ids = np.asarray(ids)
    return ids.astype(np.uint32) if ids.size and 0 <= int(ids.min()) and int(ids.max()) < 2 ** 32 else ids


def _pack_steps(step: np.ndarray) -> dict[str, np.ndarray]:
    """Per-edge quanta as stored: most edges are coded at the finest quantum (their range is
    below ``65534 * quantum``), so the most common value is stored once (``step_common``),
    a bit per edge says which have it (``step_is_common``) and the others are stored
    (``step``, :func:`_stored_step`); a map with no repeated quantum stores them all."""
    step = np.asarray(step, dtype=np.float32)
    if step.size < 16:
        return {"step": _stored_step(step)}
    vals, cnt = np.unique(step, return_counts=True)
    common = vals[np.argmax(cnt)]
    same = step == common
    if same.sum() * 2 <= 2 + step.size / 8 + 2:  # not worth a bit per edge
        return {"step": _stored_step(step)}
    return {"step_common": np.array([common], dtype=np.float32), "step_is_common": np.packbits(same),
            "step": _stored_step(step[~same])}


def _unpack_steps(arrays: dict, E: int) -> np.ndarray:
    """Inverse of :func:`_pack_steps` for ``E`` edges, float32."""
    st = np.asarray(arrays["step"], dtype=np.float32)
    if "step_common" not in arrays:
        return st
    same = np.unpackbits(np.asarray(arrays["step_is_common"], dtype=np.uint8), count=E).astype(bool)
    out = np.full(E, np.asarray(arrays["step_common"], dtype=np.float32).ravel()[0], dtype=np.float32)
    if st.size != E - int(same.sum()):
        raise ValueError(f"e-map arrays: {st.size} stored quanta for {E - int(same.sum())} edges")
    out[~same] = st
    return out


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


def _n_points(length: float, interval: float) -> int:
    """Interior points that split ``length`` into pieces no longer than ``interval``."""
    return max(math.ceil(length / interval - 1e-9) - 1, 0)


def break_thresholds(dx: float, dy: float, interval: float, tol: float) -> tuple[float, float]:
    """``(jump_min, kink_min)`` of :func:`zmap.refine._ez_kernels.detect_breaks` for an e-map
    of ``interval`` on a ``dx`` by ``dy`` grid built for ``tol``."""
    n_max = max(_n_points(dx, interval), _n_points(dy, interval)) + 1
    return tol, 4.0 * tol / n_max


def decimate(z: np.ndarray, dx: float, dy: float, interval: float, tol: float, edge_ids: np.ndarray,
             offsets: np.ndarray, heights: np.ndarray, limit: float, *, window: bool = False,
             bare: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Thin each smooth edge to the fewest evenly spaced e-points that interpolate all of its
    points linearly within ``limit``; with ``window``, thin each wall edge outside a window
    around its jump.

    The new points (``d - 1`` of them at ``t = k / d``, ``d`` from 2, 3, 4, 5, 6, 8, ...) are
    read off the edge's full sequence, linear between samples, as the cells evaluate it; so
    the thinned boundary curve is within ``limit`` of the full one everywhere (their
    difference is linear between the union of both sets of knots, zero at the new knots and
    checked at the full ones). An edge keeps all its points where its sequence has a break
    (a wall or a sharp edge, :func:`zmap.refine._ez_kernels.detect_breaks`), where the
    thinned sequence would show one, or where a height is missing: its cells split the same
    way (no break either way).

    A smooth edge whose thinned sequence shows a break gets more knots (the next counts,
    :data:`THIN_ROUNDS` tries) before it is kept whole.

    ``window``: an edge with a break (a wall's jump or a sharp edge's kink) keeps the full
    samples from :data:`WINDOW_HALF` before the break's interval to as many after it, and
    each side of them is thinned the same way to its own fewest knots (spans of 1, 2, 3, 4,
    5, 6, 8, ... intervals). The kernels read it as its full sequence, a sample outside the window
    linear between the knots of its side (:func:`zmap.refine._ez_kernels._sample`), so the
    jump, the samples either side of it and the break found are those of the full sequence
    (checked: an edge whose windowed sequence shows another break keeps all its points).

    ``bare``: a smooth edge whose corners alone interpolate its points within ``limit``
    keeps no e-point (a cell patch's sub-edges: linear between its sub-grid nodes);
    otherwise every edge keeps at least one.

    Parameters
    ----------
    z : ndarray of shape (nx, ny)
        Grid heights (the edges' corners).
    dx, dy, interval, tol : float
        Grid steps, e-map interval and tolerance (the break thresholds).
    edge_ids, offsets : ndarray of int64
        The e-edges and their CSR offsets (interior points at ``t = q / (n + 1)``).
    heights : ndarray of shape (P,), float64
        E-point heights (NaN = none).
    limit : float
        Largest difference allowed at a full point, mm.

    Returns
    -------
    offsets, heights : ndarray
        The thinned CSR offsets and heights as stored (the same edges, each still with at
        least one point unless ``bare``).
    win : ndarray of shape (E,), int64
        Packed window of each windowed edge (:func:`zmap.refine._ez_kernels.pack_window`),
        -1 for the others.
    """
    from . import _ez_kernels as _k

    E = edge_ids.shape[0]
    nowin = np.full(E, -1, dtype=np.int64)
    if E == 0:
        return offsets, heights, nowin
    heights = np.ascontiguousarray(heights, dtype=np.float64)
    n = np.diff(offsets)
    d = np.empty(E, dtype=np.int64)
    _k.decimate_counts(z, edge_ids, offsets, heights, float(limit), 1 if bare else 2, d)
    jump_min, kink_min = break_thresholds(dx, dy, interval, tol)

    def breaks(off, h, win, forced):
        kind = np.zeros(E, dtype=np.int8)
        t = np.zeros(E, dtype=np.float64)
        codes, lo, step = encode_heights(off, h, QUANTUM_SHARE * tol)
        vo = virtual_offsets(off, n, win)
        _k.detect_breaks(z, edge_ids, vo, (codes, lo, step, np.ascontiguousarray(off[:-1]), win), forced, jump_min,
                         kink_min, BREAK_RATIO, kind, t)
        return kind, t

    def thinned(dd, win):
        off = np.zeros(E + 1, dtype=np.int64)
        size = dd - 1
        w = np.flatnonzero(win >= 0)
        size[w] = [_k.window_size(int(win[k]), int(n[k])) for k in w]
        np.cumsum(size, out=off[1:])
        out = np.empty(int(off[-1]))
        _k.resample(z, edge_ids, offsets, heights, np.where(win >= 0, -1, dd - 1), off, out)
        _k.window_resample(z, edge_ids, offsets, heights, win, off, out)
        return off, out

    kind0, t0 = breaks(offsets, heights, nowin, np.zeros(E, dtype=np.int8))
    full = kind0 != 0
    # a window's break is forced: the full sequence's kind, placed inside the window
    flags = np.where(kind0 == 2, _k.WIN_FORCED | _k.WIN_KINK, _k.WIN_FORCED).astype(np.int64)
    forced = lambda w: np.where(w >= 0, w | flags, w)
    d[full] = n[full] + 1
    win = nowin.copy()
    if window:
        sel = np.flatnonzero(kind0 != 0).astype(np.int64)
        _k.window_counts(z, edge_ids, offsets, heights, t0, sel, WINDOW_HALF, float(limit), win)
        # a window that stores no fewer codes than the full edge is not one
        small = np.array([_k.window_size(int(win[k]), int(n[k])) < n[k] if win[k] >= 0 else False for k in sel],
                         dtype=bool)
        win[sel[~small]] = -1
    if not np.any((d < n + 1) | (win >= 0)):
        return offsets, heights, nowin
    off, h = thinned(d, win)
    w_limit = np.full(E, float(limit))
    for _ in range(THIN_ROUNDS + 1):
        kind1, t1 = breaks(off, h, win, np.where(win >= 0, kind0, 0).astype(np.int8))
        # a kink's place moves with the codes' quantum (the window's range is not the edge's):
        # up to KINK_SHIFT samples is the same break
        bad_w = (win >= 0) & ((kind1 != kind0) | (np.abs(t1 - t0) * (n + 1) > KINK_SHIFT))
        bad_u = (kind1 != 0) & (d < n + 1) & (win < 0)
        if not (bad_w.any() or bad_u.any()):
            break
        # a window whose knots move the break (a kink's second differences against those at
        # the knots) gets knots at a quarter of the limit, then keeps its edge whole; a
        # smooth edge whose knots show a break gets more knots (the whole edge after
        # THIN_ROUNDS tries)
        retry = bad_w & (w_limit > limit / 20.0) & (_ < THIN_ROUNDS - 1)
        if retry.any():
            w_limit[retry] /= 4.0
            for lim in np.unique(w_limit[retry]):
                sel = np.flatnonzero(retry & (w_limit == lim)).astype(np.int64)
                _k.window_counts(z, edge_ids, offsets, heights, t0, sel, WINDOW_HALF, float(lim), win)
            bad_w &= ~retry
            small = np.array([_k.window_size(int(win[k]), int(n[k])) < n[k] if win[k] >= 0 else False
                              for k in np.flatnonzero(retry)], dtype=bool)
            win[np.flatnonzero(retry)[~small]] = -1
            d[np.flatnonzero(retry)[~small]] = n[np.flatnonzero(retry)[~small]] + 1
        win[bad_w] = -1
        d[bad_w] = n[bad_w] + 1
        d[bad_u] = np.minimum(np.maximum(d[bad_u] + 1, (d[bad_u] * 5) // 4), n[bad_u] + 1)
        if _ == THIN_ROUNDS - 1:
            d[bad_u] = n[bad_u] + 1
        off, h = thinned(d, win)
    return off, h, forced(win)


def split_forced(win: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(win, forced)`` of windows that carry the flag bits :func:`decimate` returns them
    with: the windows without them, and each edge's forced break (see :class:`EZMap`)."""
    from . import _ez_kernels as _k

    win = np.asarray(win, dtype=np.int64)
    flag = (win >= 0) & ((win & _k.WIN_FORCED) != 0)
    forced = np.where(flag, np.where((win & _k.WIN_KINK) != 0, 2, 1), 0).astype(np.int8)
    return np.where(win >= 0, win & ~np.int64(_k.WIN_FORCED | _k.WIN_KINK), win), forced


def virtual_offsets(offsets: np.ndarray, full: np.ndarray | int, win: np.ndarray | None) -> np.ndarray:
    """The offsets the kernels index by: a windowed edge (``win >= 0``) counts its ``full``
    samples (an int or one per edge), the others what they store."""
    if win is None or not np.any(win >= 0):
        return offsets
    cnt = np.diff(offsets)
    w = win >= 0
    cnt[w] = np.broadcast_to(full, cnt.shape)[w]
    vo = np.zeros_like(offsets)
    np.cumsum(cnt, out=vo[1:])
    return vo


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
        (:func:`zmap.refine._ez_kernels._sample`); pass :meth:`_voff` as their offsets."""
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
            **self._count_arrays(),
            **{f"codes_{k}": v for k, v in pack_codes(self.codes, self.offsets).items()},
            **pack_offsets(self.lo, QUANTUM_SHARE * self.tol),
            **_pack_steps(self.step),
        } | self._window_arrays() | self._bubble_arrays() | {
            f"patch_{k}": v for k, v in (self.patches or CellPatches.empty()).to_arrays().items()}

    def _count_arrays(self) -> dict[str, np.ndarray]:
        """E-points stored per e-edge: in the bits the largest needs (``counts_b``, width
        ``counts_w``; format 6), or a byte each where that is no larger (``counts``)."""
        n = np.diff(self.offsets)
        w = _bit_width(n)
        if w >= 8 or n.size < 16:
            return {"counts": n.astype(np.uint8 if n.size == 0 or n.max() < 256 else np.uint16)}
        return {"counts_w": np.array([w], dtype=np.uint8), "counts_b": _pack_bits(n, w)}

    def _bubble_arrays(self) -> dict[str, np.ndarray]:
        """The bubbles as stored: their cells, and their heights as whole quanta (zigzag) in
        the bits the largest needs; none where there are none."""
        if not self.bub_cells.size:
            return {}
        q = QUANTUM_SHARE * self.tol
        k = np.rint(self.bub_h / q).astype(np.int64)
        if not np.array_equal(k * q, self.bub_h):
            raise ValueError("bubbles: heights must be whole quanta of QUANTUM_SHARE * tol")
        zz = np.where(k >= 0, 2 * k, -2 * k - 1)
        w = _bit_width(zz)
        return {"bub_cells": _narrow(self.bub_cells), "bub_q": np.array([q, w], dtype=np.float64),
                "bub_codes": _pack_bits(zz, w)}

    @staticmethod
    def _bubbles_from(arrays: dict) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Inverse of :meth:`_bubble_arrays`."""
        if "bub_cells" not in arrays:
            return None, None
        cells = np.asarray(arrays["bub_cells"]).astype(np.int64)
        q, w = (float(v) for v in np.asarray(arrays["bub_q"], dtype=np.float64).ravel())
        zz = _unpack_bits(arrays["bub_codes"], cells.size, int(w), "bubble heights")
        k = np.where(zz % 2 == 0, zz // 2, -(zz + 1) // 2)
        return cells, k * q

    def _window_arrays(self) -> dict[str, np.ndarray]:
        """The windows as stored: one bit per e-edge, and per windowed edge the first full
        sample of its break's interval ``b`` and its left knots ``dl - 1`` (uint8 or uint16);
        the rest follows from :data:`WINDOW_HALF`, the full count and the stored count.
        Format 5 adds a bit per windowed edge, its forced break a kink (``win_kink``), and
        ``win_forced`` (a bit each) only where some break is not forced (a format-4 map)."""
        from . import _ez_kernels as _k

        w = np.flatnonzero(self.win >= 0)
        if w.size == 0:
            return {}
        ww = self.win[w]
        a, c, dl = ww & 0x7FFF, (ww >> 16) & 0x7FFF, (ww >> 32) & 0xFFFF
        b = np.where(a > 0, a + WINDOW_HALF, c - 1 - WINDOW_HALF)
        nl = np.maximum(dl - 1, 0)
        dt = np.uint8 if max(int(b.max()), int(nl.max())) < 256 else np.uint16
        forced = self.forced[w] != 0
        out = {"win_bits": np.packbits(self.win >= 0), "win_b": b.astype(dt), "win_nl": nl.astype(dt),
               "win_kink": np.packbits(self.forced[w] == 2)}
        if not forced.all():
            out["win_forced"] = np.packbits(forced)
        return out

    @staticmethod
    def _windows_from(arrays: dict, edge_ids: np.ndarray, counts: np.ndarray, full: np.ndarray) -> np.ndarray | None:
        """Inverse of :meth:`_window_arrays` given the stored and full counts per e-edge
        (format 4, without ``win_kink``: no break forced)."""
        from . import _ez_kernels as _k

        if "win_bits" not in arrays:
            return None
        E = edge_ids.size
        on = np.flatnonzero(np.unpackbits(np.asarray(arrays["win_bits"], dtype=np.uint8), count=E))
        b = np.asarray(arrays["win_b"]).astype(np.int64)
        nl = np.asarray(arrays["win_nl"]).astype(np.int64)
        if b.shape != on.shape or nl.shape != on.shape:
            raise ValueError(f"e-map arrays: {b.size} window positions for {on.size} windowed edges")
        m = full[on] + 1
        a = np.maximum(b - WINDOW_HALF, 0)
        c = np.minimum(b + 1 + WINDOW_HALF, m)
        dl = np.where(a > 0, nl + 1, 0)
        nr = counts[on] - nl - (np.minimum(c, m - 1) - np.maximum(a, 1) + 1)
        dr = np.where(c < m, nr + 1, 0)
        if np.any(nr < 0) or np.any((c >= m) & (nr != 0)):
            raise ValueError("e-map arrays: a windowed edge's stored count does not fit its window")
        win = np.full(E, -1, dtype=np.int64)
        win[on] = a | (c << 16) | (dl << 32) | (dr << 48)
        if "win_kink" in arrays:
            bits = lambda name: np.unpackbits(np.asarray(arrays[name], dtype=np.uint8), count=on.size).astype(bool)
            forced = bits("win_forced") if "win_forced" in arrays else np.ones(on.size, dtype=bool)
            kink = bits("win_kink")
            win[on] |= np.where(forced, _k.WIN_FORCED, 0) | np.where(forced & kink, _k.WIN_KINK, 0)
        return win

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
            win = cls._windows_from(arrays, edge_ids, counts, full)
        else:
            edge_ids, offsets, win = arrays["edge_ids"], arrays["offsets"], None
        codes = (unpack_codes(arrays["codes_bits"], arrays["codes_w4"], offsets, arrays.get("codes_mode"),
                              arrays.get("codes_r4")) if "codes_bits" in arrays else arrays["codes"])
        bub_cells, bub_h = cls._bubbles_from(arrays)
        return cls(g[0], g[1], g[2], g[3], int(s[0]), int(s[1]), g[4], g[5], edge_ids, offsets,
                   codes, unpack_offsets(arrays, edge_ids.size), _unpack_steps(arrays, edge_ids.size), failed=int(s[2]), lifted=int(s[3]) if s.size > 3 else 0,
                   patches=patches, unresolved=int(s[4]) if s.size > 4 else 0, pruned=int(s[5]) if s.size > 5 else 0,
                   win=win, bub_cells=bub_cells, bub_h=bub_h)


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
    it (integer arithmetic on the node codes: what :meth:`CellPatches.to_arrays` stores the
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
class CellPatches:
    """Finer EZ-maps over single base cells (levels, lattices and storage: see :mod:`zmap.refine.patch`).

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
    _maps: dict = field(default_factory=dict, repr=False)

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
    def empty(cls) -> CellPatches:
        z = np.zeros(0)
        zero = np.zeros(1, dtype=np.int64)
        return cls(np.zeros(0, np.int64), np.zeros(0, np.int16), zero, z, zero, np.zeros(0, np.uint16), zero,
                   np.zeros(0, np.float32), np.zeros(0, np.float32), np.zeros(0, np.uint16))

    @classmethod
    def pack(cls, per_cell: dict[int, tuple]) -> CellPatches:
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
    def from_arrays(cls, a: dict[str, np.ndarray], grid: tuple[float, float, float] | None = None) -> CellPatches:
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

    # ---- evaluation -----------------------------------------------------------------------

    def _patch_maps(self, k: int, base: ZMap, interval: float, tol: float):
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
