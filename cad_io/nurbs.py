"""Vectorised evaluation of NURBS surfaces: points, first and second derivatives.

The kernels (Piegl & Tiller A2.1 span search, A2.3 basis derivatives, A4.4 rational
derivatives) live in :mod:`cad_io._nurbs_kernels`; this module validates, packs and
broadcasts.

Examples
--------
>>> import numpy as np
>>> from cad_io.part import NurbsSurface
>>> s = NurbsSurface(1, 1, np.array([0., 0, 1, 1]), np.array([0., 0, 1, 1]),
...                  np.array([[[0., 0, 0], [0, 1, 0]], [[1, 0, 0], [1, 1, 1]]]),
...                  np.ones((2, 2)))
>>> evaluate(s, 0.5, 0.5)[0].tolist()
[0.5, 0.5, 0.25]
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cad_io.part import NurbsSurface
from zmap.errors import NurbsError

__all__ = ["MAX_DEGREE", "PackedNurbs", "evaluate", "evaluate_packed", "pack"]

#: Highest degree the evaluation kernels accept (fixed-size stack work arrays).
MAX_DEGREE = 15

_NROW = {0: 1, 1: 3, 2: 6}
#: Batches at least this large run on all threads.
_PARALLEL_MIN = 4096


@dataclass
class PackedNurbs:
    """Many NURBS surfaces in flat arrays, the form the numba kernels take.

    Attributes
    ----------
    deg : ndarray of shape (F, 2), int64
        Degrees (p, q); -1 for a face without surface.
    ncp : ndarray of shape (F, 2), int64
        Control point counts (nu, nv); 0 for a face without surface.
    koff : ndarray of shape (F, 2), int64
        Offsets of face k's u and v knot vectors in ``knots``.
    poff : ndarray of shape (F,), int64
        Offset of face k's control points in ``cpw``.
    knots : ndarray of shape (K,), float64
        All knot vectors, concatenated (multiplicities expanded).
    cpw : ndarray of shape (N, 4), float64
        Homogeneous control points (w x, w y, w z, w) in mm; face k's pole (a, b) is row
        ``poff[k] + a * nv + b``.
    domain : ndarray of shape (F, 4), float64
        ``(u0, u1, v0, v1)`` of each face; NaN for a face without surface.
    """

    deg: np.ndarray
    ncp: np.ndarray
    koff: np.ndarray
    poff: np.ndarray
    knots: np.ndarray
    cpw: np.ndarray
    domain: np.ndarray

    @property
    def n_faces(self) -> int:
        return int(self.deg.shape[0])

    def arrays(self) -> tuple[np.ndarray, ...]:
        """``(deg, ncp, koff, poff, knots, cpw)``, the first six arguments of the kernels."""
        return self.deg, self.ncp, self.koff, self.poff, self.knots, self.cpw


def _check_surface(s: NurbsSurface, k: int) -> None:
    p, q = int(s.degree_u), int(s.degree_v)
    nu, nv = s.poles.shape[:2]
    if p > MAX_DEGREE or q > MAX_DEGREE:
        raise NurbsError(f"surface {k} has degrees ({p}, {q}), above the limit "
                         f"{MAX_DEGREE} of cad_io.nurbs")
    if p < 1 and q < 1 and (p < 0 or q < 0):
        raise NurbsError(f"surface {k} has negative degrees ({p}, {q})")
    if s.poles.ndim != 3 or s.poles.shape[2] != 3:
        raise NurbsError(f"surface {k}: poles must have shape (nu, nv, 3), got {s.poles.shape}")
    if s.weights.shape != (nu, nv):
        raise NurbsError(f"surface {k}: weights must have shape {(nu, nv)}, "
                         f"got {s.weights.shape}")
    if len(s.knots_u) != nu + p + 1 or len(s.knots_v) != nv + q + 1:
        raise NurbsError(f"surface {k}: knot vectors of lengths ({len(s.knots_u)}, "
                         f"{len(s.knots_v)}) do not match {nu}x{nv} poles of degrees "
                         f"({p}, {q}); expected ({nu + p + 1}, {nv + q + 1})")
    if np.any(np.diff(s.knots_u) < 0) or np.any(np.diff(s.knots_v) < 0):
        raise NurbsError(f"surface {k}: knot vectors must be non-decreasing")
    if not np.all(s.weights > 0):
        raise NurbsError(f"surface {k}: weights must be positive")


def pack(surfaces: list[NurbsSurface | None]) -> PackedNurbs:
    """Pack surfaces into flat arrays for the kernels.

    Parameters
    ----------
    surfaces : list of NurbsSurface or None
        One entry per face; None for a face without surface (its ``deg`` is -1).

    Returns
    -------
    PackedNurbs

    Raises
    ------
    zmap.errors.NurbsError
        A surface with inconsistent arrays or a degree above :data:`MAX_DEGREE`.

    Examples
    --------
    >>> import numpy as np
    >>> from cad_io.part import NurbsSurface
    >>> s = NurbsSurface(1, 1, np.array([0., 0, 1, 1]), np.array([0., 0, 1, 1]),
    ...                  np.zeros((2, 2, 3)), np.ones((2, 2)))
    >>> pack([s, None]).deg.tolist()
    [[1, 1], [-1, -1]]
    """
    F = len(surfaces)
    deg = np.full((F, 2), -1, dtype=np.int64)
    ncp = np.zeros((F, 2), dtype=np.int64)
    koff = np.zeros((F, 2), dtype=np.int64)
    poff = np.zeros(F, dtype=np.int64)
    domain = np.full((F, 4), np.nan)
    knots: list[np.ndarray] = []
    cpw: list[np.ndarray] = []
    nk = 0
    npole = 0
    for k, s in enumerate(surfaces):
        koff[k] = nk
        poff[k] = npole
        if s is None:
            continue
        _check_surface(s, k)
        nu, nv = s.poles.shape[:2]
        deg[k] = s.degree_u, s.degree_v
        ncp[k] = nu, nv
        ku = np.ascontiguousarray(s.knots_u, dtype=np.float64)
        kv = np.ascontiguousarray(s.knots_v, dtype=np.float64)
        koff[k] = nk, nk + len(ku)
        knots += [ku, kv]
        nk += len(ku) + len(kv)
        w = np.asarray(s.weights, dtype=np.float64).reshape(nu * nv, 1)
        pw = np.hstack([np.asarray(s.poles, dtype=np.float64).reshape(nu * nv, 3) * w, w])
        cpw.append(pw)
        npole += nu * nv
        domain[k] = s.domain
    return PackedNurbs(
        deg=deg, ncp=ncp, koff=koff, poff=poff,
        knots=np.concatenate(knots) if knots else np.zeros(0),
        cpw=np.ascontiguousarray(np.vstack(cpw)) if cpw else np.zeros((0, 4)),
        domain=domain,
    )


def _check_derivs(derivs: int) -> int:
    if derivs not in _NROW:
        raise ValueError(f"derivs={derivs!r} is not one of 0, 1, 2")
    return int(derivs)


def evaluate_packed(packed: PackedNurbs, face, u, v, *, derivs: int = 0) -> np.ndarray:
    """Evaluate packed surfaces at many (face, u, v).

    Parameters
    ----------
    packed : PackedNurbs
    face : array_like of int
        Face indices into ``packed``; broadcast with ``u`` and ``v``.
    u, v : array_like of float
        Parameters; values outside a face's domain are clamped to it; NaN gives NaN.
    derivs : {0, 1, 2}, keyword-only
        Highest derivative order.

    Returns
    -------
    ndarray of shape broadcast(face, u, v).shape + (1 | 3 | 6, 3), float64
        Rows S, Su, Sv, Suu, Suv, Svv in mm (per unit parameter); NaN for faces without
        surface.

    Examples
    --------
    >>> import numpy as np
    >>> from cad_io.part import NurbsSurface
    >>> s = NurbsSurface(1, 1, np.array([0., 0, 1, 1]), np.array([0., 0, 1, 1]),
    ...                  np.array([[[0., 0, 0], [0, 1, 0]], [[1, 0, 0], [1, 1, 1]]]),
    ...                  np.ones((2, 2)))
    >>> evaluate_packed(pack([s]), [0, 0], [0.0, 1.0], 1.0)[:, 0].tolist()
    [[0.0, 1.0, 0.0], [1.0, 1.0, 1.0]]
    """
    from cad_io._nurbs_kernels import eval_many, eval_many_serial

    derivs = _check_derivs(derivs)
    f, uu, vv = np.broadcast_arrays(np.asarray(face), np.asarray(u, dtype=np.float64),
                                    np.asarray(v, dtype=np.float64))
    shape = f.shape
    f = np.ascontiguousarray(f.ravel(), dtype=np.int64)
    if f.size and (f.min() < 0 or f.max() >= packed.n_faces):
        bad = f[(f < 0) | (f >= packed.n_faces)][0]
        raise IndexError(f"face {bad} out of range for {packed.n_faces} packed surfaces")
    out = np.empty((f.size, _NROW[derivs], 3))
    if f.size:
        kernel = eval_many if f.size >= _PARALLEL_MIN else eval_many_serial
        kernel(*packed.arrays(), f, np.ascontiguousarray(uu.ravel()),
                  np.ascontiguousarray(vv.ravel()), derivs, out)
    return out.reshape(shape + out.shape[1:])


def evaluate(surface: NurbsSurface, u, v, *, derivs: int = 0) -> np.ndarray:
    """Evaluate one NURBS surface at many (u, v).

    Parameters
    ----------
    surface : NurbsSurface
    u, v : array_like of float
        Parameters, broadcast together; clamped to ``surface.domain``.
    derivs : {0, 1, 2}, keyword-only

    Returns
    -------
    ndarray of shape broadcast(u, v).shape + (1 | 3 | 6, 3), float64
        Rows S, Su, Sv, Suu, Suv, Svv.

    Examples
    --------
    >>> import numpy as np
    >>> from cad_io.part import NurbsSurface
    >>> s = NurbsSurface(1, 1, np.array([0., 0, 1, 1]), np.array([0., 0, 1, 1]),
    ...                  np.array([[[0., 0, 0], [0, 1, 0]], [[1, 0, 0], [1, 1, 1]]]),
    ...                  np.ones((2, 2)))
    >>> evaluate(s, 0.5, 0.5, derivs=2)[4].tolist()  # Suv
    [0.0, 0.0, 1.0]
    """
    return evaluate_packed(pack([surface]), 0, u, v, derivs=derivs)
