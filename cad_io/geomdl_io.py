"""Build a :class:`~cad_io.part.Part` from geomdl NURBS or B-spline surfaces.

geomdl surfaces are untrimmed, so every face has ``loops == []``. The four boundary curves
of each surface become edges; where two surfaces share a boundary curve (the same points,
in either direction) the edge joins both faces and carries their dihedral angle,
otherwise it is an open boundary edge.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np

from cad_io.part import Edge, Face, NurbsSurface, Part

__all__ = ["from_geomdl", "to_nurbs_surface"]

#: Samples along each boundary curve (edge polylines and the shared-boundary test).
_EDGE_SAMPLES = 33


def to_nurbs_surface(surface: Any, index: int = 0) -> NurbsSurface:
    """The :class:`NurbsSurface` of one geomdl ``NURBS.Surface`` or ``BSpline.Surface``.

    Parameters
    ----------
    surface : geomdl surface
        3D, with its control points, weights (NURBS) and knot vectors set.
    index : int
        Position in the caller's list, for error messages.

    Examples
    --------
    >>> from geomdl import BSpline
    >>> s = BSpline.Surface()
    >>> s.degree_u, s.degree_v = 1, 1
    >>> s.ctrlpts_size_u, s.ctrlpts_size_v = 2, 2
    >>> s.ctrlpts = [[0, 0, 0], [0, 1, 0], [1, 0, 0], [1, 1, 1]]
    >>> s.knotvector_u = s.knotvector_v = [0, 0, 1, 1]
    >>> to_nurbs_surface(s).poles[1, 1].tolist()
    [1.0, 1.0, 1.0]
    """
    for attr in ("degree_u", "degree_v", "ctrlpts", "knotvector_u", "knotvector_v"):
        if not hasattr(surface, attr):
            raise TypeError(f"surface {index} must be a geomdl NURBS or BSpline Surface, "
                            f"got {type(surface).__name__}")
    p, q = int(surface.degree_u), int(surface.degree_v)
    nu, nv = int(surface.ctrlpts_size_u), int(surface.ctrlpts_size_v)
    pts = np.asarray(surface.ctrlpts, dtype=np.float64)
    if pts.ndim != 2 or pts.shape != (nu * nv, 3):
        raise ValueError(f"surface {index} must have {nu}x{nv} 3D control points, got "
                         f"array of shape {pts.shape}")
    w = getattr(surface, "weights", None)
    weights = (np.ones((nu, nv)) if w is None or len(w) == 0
               else np.asarray(w, dtype=np.float64).reshape(nu, nv))
    # geomdl orders control points with v running fastest: index = a * nv + b
    return NurbsSurface(p, q, np.asarray(surface.knotvector_u, dtype=np.float64),
                        np.asarray(surface.knotvector_v, dtype=np.float64),
                        pts.reshape(nu, nv, 3), weights)


def _bbox(s: NurbsSurface) -> tuple[float, ...]:
    """Sampled box, widened by the sampling's chordal error and clipped to the poles' box."""
    from cad_io.nurbs import evaluate

    u0, u1, v0, v1 = s.domain
    n_u = max(33, 4 * (s.poles.shape[0] - s.degree_u + 1) + 1)
    n_v = max(33, 4 * (s.poles.shape[1] - s.degree_v + 1) + 1)
    u = np.linspace(u0, u1, n_u)
    v = np.linspace(v0, v1, n_v)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    pts = evaluate(s, uu, vv)[..., 0, :]
    um, vm = np.meshgrid(0.5 * (u[:-1] + u[1:]), 0.5 * (v[:-1] + v[1:]), indexing="ij")
    mid = evaluate(s, um, vm)[..., 0, :]
    corners = 0.25 * (pts[:-1, :-1] + pts[1:, :-1] + pts[:-1, 1:] + pts[1:, 1:])
    margin = float(np.max(np.linalg.norm(mid - corners, axis=-1))) * 2.0
    lo = np.minimum(pts.reshape(-1, 3).min(0), mid.reshape(-1, 3).min(0)) - margin
    hi = np.maximum(pts.reshape(-1, 3).max(0), mid.reshape(-1, 3).max(0)) + margin
    plo = s.poles.reshape(-1, 3).min(0)
    phi = s.poles.reshape(-1, 3).max(0)
    return (*np.maximum(lo, plo).tolist(), *np.minimum(hi, phi).tolist())


def _boundaries(s: NurbsSurface):
    """The four boundary curves: (points (n, 3), u (n,), v (n,)) each."""
    from cad_io.nurbs import evaluate

    u0, u1, v0, v1 = s.domain
    t = np.linspace(0.0, 1.0, _EDGE_SAMPLES)
    out = []
    for uu, vv in ((u0 + (u1 - u0) * t, np.full_like(t, v0)),
                   (np.full_like(t, u1), v0 + (v1 - v0) * t),
                   (u0 + (u1 - u0) * t[::-1], np.full_like(t, v1)),
                   (np.full_like(t, u0), v0 + (v1 - v0) * t[::-1])):
        out.append((evaluate(s, uu, vv)[:, 0], uu, vv))
    return out


def _normals(s: NurbsSurface, u, v, reversed_: bool) -> np.ndarray:
    from cad_io.nurbs import evaluate

    d = evaluate(s, u, v, derivs=1)
    n = np.cross(d[:, 1], d[:, 2])
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        n = np.where(ln > 0, n / ln, np.nan)
    return -n if reversed_ else n


def _edges(faces: list[Face]) -> list[Edge]:
    bnds = [(f.index, k, *b) for f in faces for k, b in enumerate(_boundaries(f.surface))]
    scale = max(1.0, float(np.nanmax(np.abs([f.bbox for f in faces]))))
    tol = 1e-6 * scale
    used = [False] * len(bnds)
    edges: list[Edge] = []
    for i, (fi, _, pi, ui, vi) in enumerate(bnds):
        if used[i]:
            continue
        used[i] = True
        if np.max(np.linalg.norm(pi - pi[0], axis=1)) <= tol:
            continue  # collapsed boundary (a pole)
        adj = [fi]
        dihedral = np.nan
        ni = _normals(faces[fi].surface, ui, vi, faces[fi].reversed)
        for j in range(i + 1, len(bnds)):
            fj, _, pj, uj, vj = bnds[j]
            if used[j]:
                continue
            for flip in (False, True):
                q = pj[::-1] if flip else pj
                if np.max(np.linalg.norm(q - pi, axis=1)) <= tol:
                    used[j] = True
                    adj.append(fj)
                    nj = _normals(faces[fj].surface, uj[::-1] if flip else uj,
                                  vj[::-1] if flip else vj, faces[fj].reversed)
                    c = np.clip(np.einsum("ij,ij->i", ni, nj), -1.0, 1.0)
                    ang = np.arccos(c)
                    if np.any(np.isfinite(ang)):
                        m = float(np.nanmax(ang))
                        dihedral = m if not np.isfinite(dihedral) else max(dihedral, m)
                    break
        edges.append(Edge(index=len(edges), faces=tuple(adj), points=pi,
                          dihedral=dihedral if len(adj) > 1 else np.nan))
    return edges


def from_geomdl(surfaces: Any, *, source: str = "geomdl") -> Part:
    """A :class:`Part` whose faces are geomdl surfaces (untrimmed).

    Parameters
    ----------
    surfaces : geomdl Surface or iterable of them
        ``geomdl.NURBS.Surface`` or ``geomdl.BSpline.Surface`` (a container of them works
        too); 3D control points, knot vectors with multiplicities expanded.
    source : str, keyword-only
        Recorded in ``Part.source``.

    Returns
    -------
    Part
        One face per surface (kind ``'bspline'``, ``reversed`` False, ``loops`` empty),
        boundary edges joined where two surfaces share a boundary curve, ``shape`` None.

    Raises
    ------
    TypeError
        An entry that is not a geomdl surface.
    ValueError
        No surfaces, or a surface with inconsistent control points or knots.

    Examples
    --------
    >>> from geomdl import BSpline
    >>> s = BSpline.Surface()
    >>> s.degree_u, s.degree_v = 1, 1
    >>> s.ctrlpts_size_u, s.ctrlpts_size_v = 2, 2
    >>> s.ctrlpts = [[0, 0, 0], [0, 1, 0], [1, 0, 0], [1, 1, 1]]
    >>> s.knotvector_u = s.knotvector_v = [0, 0, 1, 1]
    >>> part = from_geomdl(s)
    >>> len(part.faces), len(part.edges), part.edges[0].is_boundary
    (1, 4, True)
    """
    from cad_io.nurbs import pack

    if hasattr(surfaces, "ctrlpts"):
        surfaces = [surfaces]
    if not isinstance(surfaces, Iterable):
        raise TypeError(f"surfaces must be a geomdl surface or an iterable of them, got "
                        f"{type(surfaces).__name__}")
    nurbs = [to_nurbs_surface(s, i) for i, s in enumerate(surfaces)]
    if not nurbs:
        raise ValueError("from_geomdl needs at least one surface, got none")
    pack(nurbs)  # validates knots, weights and degrees with clear messages
    faces = [Face(index=i, kind="bspline", surface=s, reversed=False, loops=[],
                  bbox=_bbox(s)) for i, s in enumerate(nurbs)]
    return Part(faces=faces, edges=_edges(faces), source=source, shape=None)
