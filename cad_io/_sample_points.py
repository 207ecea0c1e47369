"""The z-map sampler at scattered points: exact top-most heights of a part at any xy, by the
grid sampler's method per point, and the height function the refinement steps take.

The part's face set is meshed once per deflection and axis and kept on the part
(:func:`cad_io._sample_faces._cached_face_set`), so repeated calls pay only for the points.
"""

from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np

from ._sample_faces import _FaceSet, _cached_face_set
from ._sample_pairs import _MODE, METHODS, NEWTON_MAX_ITER, NEWTON_TOL, _run_pairs
from .part import Part
from .view import check_axis

__all__ = ["POINTS_CHUNK", "POINTS_DEFLECTION", "_bins", "height_function", "sample_points"]

#: default mesh deflection (mm) of :func:`sample_points`: starts and facet fallback heights
POINTS_DEFLECTION = 0.01
#: scattered points solved per pass of :func:`sample_points` (bounds its working memory)
POINTS_CHUNK = 1_000_000


def _bins(px: np.ndarray, py: np.ndarray, fs: _FaceSet) -> tuple[Any, ...]:
    """Square bins over the points, CSR lists of the points in each (see ``count_pairs_xy``)."""
    n = len(px)
    bx0, by0 = float(px.min()), float(py.min())
    wx, wy = float(px.max()) - bx0, float(py.max()) - by0
    # about one point per bin, but no bin much smaller than a typical triangle
    e = fs.nodes[fs.tris[:, 1], :2] - fs.nodes[fs.tris[:, 0], :2]
    tri_len = float(np.median(np.hypot(e[:, 0], e[:, 1]))) if len(e) else 1.0
    bh = max(math.sqrt(max(wx * wy, 1e-12) / max(n, 1)), 0.25 * tri_len, 1e-6)
    while (wx / bh + 1) * (wy / bh + 1) > 4 * n + 16:
        bh *= 1.5
    nbx = int(wx / bh) + 1
    nby = int(wy / bh) + 1
    key = np.minimum(((px - bx0) / bh).astype(np.int64), nbx - 1) * nby + np.minimum(
        ((py - by0) / bh).astype(np.int64), nby - 1)
    order = np.argsort(key, kind="stable").astype(np.int64)
    ptr = np.zeros(nbx * nby + 1, dtype=np.int64)
    np.cumsum(np.bincount(key, minlength=nbx * nby), out=ptr[1:])
    return bx0, by0, bh, nbx, nby, ptr, order


def sample_points(part: Part, x: Any, y: Any, *, deflection: float | None = None, method: str = "auto",
                  axis: str = "+z") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact top-most heights of a part at scattered xy (the grid sampler's method per point).

    Every mesh triangle that covers a point in xy gives a start for the 2D Jacobian
    inversion on its face's NURBS, with the trim test and facet fallback of
    :func:`cad_io.sampler.sample`
    (the same kernel solves both); the top-most candidate wins.

    Parameters
    ----------
    part : cad_io.Part
        Meshed on first use at ``deflection``; the packed faces are cached on the part per
        deflection and axis, so repeated calls pay only for the points.
    x, y : array_like of float, broadcastable
        World (view-frame) coordinates in mm.
    deflection : float, optional
        Mesh deflection in mm for starts and facet heights; default
        :data:`POINTS_DEFLECTION` (0.01).
    method : {'auto', 'jacobian', 'facet'}
        As in :func:`cad_io.sampler.sample`.
    axis : str
        View axis, as in :func:`cad_io.sampler.sample`.

    Returns
    -------
    z : ndarray of float64 (broadcast shape)
        Heights in mm, NaN where no face covers the point (or for NaN input).
    face : ndarray of int32
        Face index that gave each height, -1 where none.
    method : ndarray of int8
        0 empty, 1 Jacobian inversion, 2 facet.

    Examples
    --------
    >>> from pathlib import Path
    >>> import cad_io
    >>> part = cad_io.read_step(Path(cad_io.__file__).parents[1] / "data" / "boss.step")
    >>> z, face, how = sample_points(part, [-15.0, 22.0, 100.0], [5.0, -12.0, 0.0])
    >>> z.round(9).tolist(), how.tolist()
    ([22.0, 16.0, nan], [1, 1, 0])
    """
    from . import _sample_kernels as K

    if method not in _MODE:
        raise ValueError(f"method={method!r} is not one of {', '.join(repr(m) for m in METHODS)}")
    check_axis(axis)
    if not part.faces:
        raise ValueError(f"part {part.source!r} has no faces")
    deflection = POINTS_DEFLECTION if deflection is None else float(deflection)
    if not (math.isfinite(deflection) and deflection > 0):
        raise ValueError(f"deflection must be positive, got {deflection!r}")
    xb, yb = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
    shape = xb.shape
    px = np.ascontiguousarray(xb).ravel()
    py = np.ascontiguousarray(yb).ravel()
    n = px.size
    zflat = np.full(n, np.nan)
    fflat = np.full(n, -1, dtype=np.int32)
    mflat = np.zeros(n, dtype=np.int8)
    good = np.flatnonzero(np.isfinite(px) & np.isfinite(py))
    fs = _cached_face_set(part, deflection, axis)
    if fs.tris is None:
        return zflat.reshape(shape), fflat.reshape(shape), mflat.reshape(shape)
    mode = _MODE[method]
    # points in chunks: the bins and working arrays take ~100 bytes a point, and an EZ-map
    # asks for all its e-points at once (bm2_ec_t4-A: 8 GB in one call before chunking)
    for c0 in range(0, good.size, POINTS_CHUNK):
        sel = good[c0:c0 + POINTS_CHUNK]
        gx = np.ascontiguousarray(px[sel])
        gy = np.ascontiguousarray(py[sel])
        bins = _bins(gx, gy, fs)
        counts = np.zeros(len(fs.tris), dtype=np.int64)
        K.count_pairs_xy(fs.nodes, fs.tris, fs.tri_margin, gx, gy, *bins, counts)

        def fill(t, offsets, gidx, tri_p, w, gx=gx, gy=gy, bins=bins):
            K.fill_pairs_xy(fs.nodes, fs.tris, fs.tri_margin, t, offsets, gx, gy, *bins, gidx, tri_p, w)

        def solve(gidx, tri_p, w, zc, st, gx=gx, gy=gy):
            K.solve_pairs_xy(gidx, tri_p, w, *fs.solve_args(), gx, gy, mode, NEWTON_TOL, NEWTON_MAX_ITER, zc, st)

        zg = np.full(sel.size, np.nan)
        fg = np.full(sel.size, -1, dtype=np.int32)
        mg = np.zeros(sel.size, dtype=np.int8)
        _run_pairs(fs, counts, fill, solve, zg, fg, mg)
        zflat[sel] = zg
        fflat[sel] = fg
        mflat[sel] = mg
    return zflat.reshape(shape), fflat.reshape(shape), mflat.reshape(shape)


def height_function(part: Part, **kwargs: Any) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """``heights(x, y) -> z``: the part's top-most heights as the refinement steps take them.

    Parameters
    ----------
    part : cad_io.Part
    **kwargs
        ``deflection``, ``method``, ``axis`` of :func:`sample_points`.

    Returns
    -------
    callable
        ``heights(x, y)`` returns float64 heights (broadcast shape), NaN where there is no
        surface. Its attribute ``last_method`` holds the method codes of the latest call, so a
        caller can count facet answers (code 2).

    Examples
    --------
    >>> from pathlib import Path
    >>> import cad_io
    >>> part = cad_io.read_step(Path(cad_io.__file__).parents[1] / "data" / "pocket.step")
    >>> h = height_function(part)
    >>> h(np.array([0.0]), np.array([0.0])).round(9).tolist()
    [15.0]
    """
    unknown = set(kwargs) - {"deflection", "method", "axis"}
    if unknown:
        raise TypeError(f"height_function got unexpected options {sorted(unknown)}; "
                        f"it takes 'deflection', 'method', 'axis'")

    def heights(x, y):
        z, _face, how = sample_points(part, x, y, **kwargs)
        heights.last_method = how
        return z

    heights.last_method = np.zeros(0, dtype=np.int8)
    heights.part = part
    return heights
