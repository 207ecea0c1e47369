"""The e-map's height codes and how they are stored (format 6).

Heights are coded per segment (an edge, a patch, a lattice) as 16-bit integers over the
segment's range, ``height = lo + step * code`` (:func:`encode_heights`; :data:`NAN_CODE` for
none), no finer than the finest quantum, :data:`QUANTUM_SHARE` of the tolerance. Stored, a
segment's codes take the bits their range needs, plainly or as second differences
(:func:`pack_codes`); the offsets are whole quanta on one lattice (:func:`pack_offsets`), the
quanta float16 behind their common value (:func:`_pack_steps`), and the e-edges' point counts
(:func:`pack_edge_counts`) and the bubbles (:func:`pack_bubbles`) take the bits the largest
needs. Each ``unpack_*`` restores what its ``pack_*`` stored exactly.
"""

from __future__ import annotations

import numpy as np

__all__ = ["NAN_CODE", "QUANTUM_SHARE", "_bit_width", "_narrow", "_nibbles", "_pack_bits", "_pack_steps",
           "_segment_cumsum", "_stored_step", "_unnibble", "_unpack_bits", "_unpack_steps", "encode_heights",
           "half_step", "pack_bubbles", "pack_codes", "pack_edge_counts", "pack_offsets", "unpack_bubbles",
           "unpack_codes", "unpack_offsets"]

#: 16-bit code of an e-point with no height; valid codes are 0 .. NAN_CODE - 1.
NAN_CODE = 65535
#: The finest quantum of the coded heights, as a share of the tolerance (:func:`encode_heights`'s
#: ``quantum``): tol/32 = 3.1e-4 mm at tol 0.01 (an error of at most 1.6e-4 mm), about the
#: quantum of a 20 mm wall's 16-bit codes (the paper's Table 2 codes), so no height is coded
#: finer than it needs; stored, an edge's codes take the bits their range needs at that
#: quantum (:func:`pack_codes`), and its offset is a whole number of quanta
#: (:func:`pack_offsets`). Every cell is checked against the exact surface as coded.
QUANTUM_SHARE = 1.0 / 32.0


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


def pack_edge_counts(n: np.ndarray) -> dict[str, np.ndarray]:
    """E-points stored per e-edge, as stored: in the bits the largest needs (``counts_b``,
    width ``counts_w``; format 6), or a byte each where that is no larger (``counts``).

    Parameters
    ----------
    n : ndarray of shape (E,), int64
        Codes each e-edge stores.

    Returns
    -------
    dict of str to ndarray
        The stored arrays (:meth:`zmap.refine._emap.EZMap.from_arrays` reads them).
    """
    w = _bit_width(n)
    if w >= 8 or n.size < 16:
        return {"counts": n.astype(np.uint8 if n.size == 0 or n.max() < 256 else np.uint16)}
    return {"counts_w": np.array([w], dtype=np.uint8), "counts_b": _pack_bits(n, w)}


def pack_bubbles(bub_cells: np.ndarray, bub_h: np.ndarray, tol: float) -> dict[str, np.ndarray]:
    """The bubbles of an e-map as stored: their cells, and their heights as whole quanta
    (zigzag) in the bits the largest needs; none where there are none.

    Parameters
    ----------
    bub_cells : ndarray of shape (B,), int64
        Sorted flat ids of the cells with a bubble (:class:`zmap.refine._emap.EZMap`).
    bub_h : ndarray of shape (B,), float64
        Their heights, mm: whole quanta of ``QUANTUM_SHARE * tol``.
    tol : float
        The e-map's tolerance, mm.

    Returns
    -------
    dict of str to ndarray
        ``bub_cells``, ``bub_q`` (quantum and width) and ``bub_codes``; empty without bubbles.

    Raises
    ------
    ValueError
        Where a height is not a whole number of quanta.
    """
    if not bub_cells.size:
        return {}
    q = QUANTUM_SHARE * tol
    k = np.rint(bub_h / q).astype(np.int64)
    if not np.array_equal(k * q, bub_h):
        raise ValueError("bubbles: heights must be whole quanta of QUANTUM_SHARE * tol")
    zz = np.where(k >= 0, 2 * k, -2 * k - 1)
    w = _bit_width(zz)
    return {"bub_cells": _narrow(bub_cells), "bub_q": np.array([q, w], dtype=np.float64),
            "bub_codes": _pack_bits(zz, w)}


def unpack_bubbles(arrays: dict) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Inverse of :func:`pack_bubbles`: ``(bub_cells, bub_h)``, ``(None, None)`` without bubbles.

    Parameters
    ----------
    arrays : dict of str to ndarray
        An e-map's stored arrays.

    Returns
    -------
    bub_cells : ndarray of shape (B,), int64, or None
    bub_h : ndarray of shape (B,), float64, or None
    """
    if "bub_cells" not in arrays:
        return None, None
    cells = np.asarray(arrays["bub_cells"]).astype(np.int64)
    q, w = (float(v) for v in np.asarray(arrays["bub_q"], dtype=np.float64).ravel())
    zz = _unpack_bits(arrays["bub_codes"], cells.size, int(w), "bubble heights")
    k = np.where(zz % 2 == 0, zz // 2, -(zz + 1) // 2)
    return cells, k * q
