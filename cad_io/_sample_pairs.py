"""The pair loop of the z-map sampler (:mod:`cad_io.sampler`): its methods, its Newton
settings and the chunked fill-solve-reduce driver that the grid, scattered-point and tiled
samplers share.

A pair is (point, mesh triangle that covers it in xy), one candidate height; the kernels
that fill, solve and reduce pairs are :mod:`cad_io._sample_kernels`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Callable

import numpy as np

if TYPE_CHECKING:
    from ._sample_faces import _FaceSet

__all__ = ["CHUNK_PAIRS", "EMPTY", "FACET", "JACOBIAN", "METHODS", "NEWTON_MAX_ITER", "NEWTON_TOL", "_MODE",
           "_run_pairs"]

METHODS = ("auto", "jacobian", "facet")
EMPTY, JACOBIAN, FACET = 0, 1, 2
_MODE = {"auto": 0, "jacobian": 1, "facet": 2}

#: pairs (grid point, triangle) solved per kernel call; bounds the working memory and the
#: time between two checks for Ctrl-C (a kernel call cannot be interrupted)
CHUNK_PAIRS = 131_072
#: Newton: xy residual (mm) at which a solution counts as converged, and iteration cap
NEWTON_TOL = 1e-10
NEWTON_MAX_ITER = 30


def _run_pairs(fs: _FaceSet, counts: np.ndarray, fill: Callable[..., None], solve: Callable[..., None],
               zflat: np.ndarray, fflat: np.ndarray, mflat: np.ndarray,
               update: Callable[[int], None] | None = None) -> int:
    """Fill, solve and reduce the pairs of every triangle, at most CHUNK_PAIRS at a time.

    Parameters
    ----------
    fs : _FaceSet
        The packed faces (:func:`cad_io._sample_faces._face_set`).
    counts : ndarray of int64, shape (M,)
        Pairs per triangle of ``fs``.
    fill, solve : callable
        ``fill(t, offsets, gidx, tri, w)`` and ``solve(gidx, tri, w, z, status)``: the grid,
        scattered-point or tile kernels.
    zflat, fflat, mflat : ndarray
        Height, face and method per point, updated in place with the top-most candidates.
    update : callable, optional
        ``update(n)`` after each chunk of ``n`` pairs (progress).

    Returns
    -------
    int
        The number of pairs.
    """
    from . import _sample_kernels as K

    cum = np.concatenate([[0], np.cumsum(counts)])
    n_pairs = int(cum[-1])
    t = 0
    M = len(counts)
    while t < M:
        # triangles t..t1-1 hold at most CHUNK_PAIRS pairs (or one triangle)
        t1 = int(np.searchsorted(cum, cum[t] + CHUNK_PAIRS, side="right")) - 1
        t1 = min(max(t1, t + 1), M)
        offsets = np.ascontiguousarray(cum[t:t1 + 1] - cum[t])
        P = int(offsets[-1])
        if P:
            gidx = np.empty(P, dtype=np.int64)
            tri_p = np.empty(P, dtype=np.int64)
            w = np.empty((P, 2))
            fill(t, offsets, gidx, tri_p, w)
            zc = np.empty(P)
            st = np.empty(P, dtype=np.int8)
            solve(gidx, tri_p, w, zc, st)
            K.reduce_pairs(gidx, tri_p, fs.tri_face, zc, st, zflat, fflat, mflat)
            if update is not None:
                update(P)
        t = t1
    return n_pairs
