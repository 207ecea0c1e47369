"""The kernel-free description of a part: faces as exact NURBS, trim loops, edges.

A :class:`Part` holds plain numpy arrays only, so the sampler and the refinement steps work
on it without the CAD kernel; ``Part.shape`` keeps the OCP shape (when read from STEP) for
the facet path and for reference checks.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["NurbsSurface", "Face", "Edge", "Part", "FaceMesh"]


@dataclass
class NurbsSurface:
    """A (rational) B-spline surface, non-periodic, clamped or not.

    Parameters
    ----------
    degree_u, degree_v : int
    knots_u : ndarray of shape (nu + degree_u + 1,), float64
        Full knot vector (multiplicities expanded).
    knots_v : ndarray of shape (nv + degree_v + 1,), float64
    poles : ndarray of shape (nu, nv, 3), float64
        Control points in mm, ``poles[a, b]`` multiplies ``N_a(u) N_b(v)``.
    weights : ndarray of shape (nu, nv), float64
        All ones for a non-rational surface.
    """

    degree_u: int
    degree_v: int
    knots_u: np.ndarray
    knots_v: np.ndarray
    poles: np.ndarray
    weights: np.ndarray

    @property
    def rational(self) -> bool:
        return bool(np.any(self.weights != self.weights.flat[0]))

    @property
    def domain(self) -> tuple[float, float, float, float]:
        """``(u0, u1, v0, v1)`` of the valid parameter range."""
        pu, pv = self.degree_u, self.degree_v
        return (float(self.knots_u[pu]), float(self.knots_u[-pu - 1]),
                float(self.knots_v[pv]), float(self.knots_v[-pv - 1]))


@dataclass
class FaceMesh:
    """Triangles of one face: 3D nodes, their (u, v) on the face's NURBS when known."""

    nodes: np.ndarray  # (n, 3) float64, mm
    triangles: np.ndarray  # (m, 3) int32, indices into nodes
    uv: np.ndarray | None = None  # (n, 2) float64 in the NurbsSurface's parameters, or None
    deflection: float = 0.0


@dataclass
class Face:
    """One trimmed face of the part.

    Parameters
    ----------
    index : int
        0-based position in ``Part.faces`` (the order of OCC's face explorer).
    kind : str
        Original surface type: 'plane', 'cylinder', 'cone', 'sphere', 'torus', 'bspline',
        'bezier', 'revolution', 'extrusion', 'offset', 'other'.
    surface : NurbsSurface or None
        Exact NURBS form; None where conversion failed (the face then goes to facets).
    reversed : bool
        True where the face's orientation is reversed against its surface's normal.
    loops : list of ndarray of shape (n, 2)
        Trim loops in the NurbsSurface's (u, v), closed polylines (first point not
        repeated): ``loops[0]`` is the outer loop, the rest are holes. Empty = untrimmed.
    bbox : tuple of float
        ``(xmin, ymin, zmin, xmax, ymax, zmax)`` of the trimmed face, mm.
    """

    index: int
    kind: str
    surface: NurbsSurface | None
    reversed: bool = False
    loops: list[np.ndarray] = field(default_factory=list)
    bbox: tuple[float, float, float, float, float, float] = (np.nan,) * 6
    mesh: FaceMesh | None = None
    #: The OCP ``TopoDS_Face`` (oriented as in the part) whose surface ``surface`` is and
    #: whose pcurves ``loops`` sample; None for geomdl input.
    topo: Any = field(default=None, repr=False, compare=False)
    #: Largest tolerance (mm) of the face's edges in the file: its trim curves may lie that
    #: far from the true boundary (0 when unknown, e.g. geomdl input).
    tolerance: float = 0.0
    #: Per loop of ``loops``, per chord (from point i to point i + 1, the last back to the
    #: first): the true trim curve runs ``bulge * s * (1 - s)`` (uv) to the chord's left at
    #: the fraction ``s`` along it; empty when unknown (geomdl input).
    loop_bulges: list[np.ndarray] = field(default_factory=list)


@dataclass
class Edge:
    """An edge of the part with its adjacent faces.

    Parameters
    ----------
    index : int
    faces : tuple of int
        Indices of the adjacent faces (one for an open boundary edge, two for a manifold
        edge; more for a non-manifold one).
    points : ndarray of shape (n, 3)
        Polyline along the edge, mm.
    dihedral : float
        Largest angle in radians between the adjacent faces' outward normals along the edge
        (0 = smooth, pi/2 = right-angle edge); NaN for an open boundary edge.
    """

    index: int
    faces: tuple[int, ...]
    points: np.ndarray
    dihedral: float = np.nan

    @property
    def is_boundary(self) -> bool:
        return len(self.faces) == 1


@dataclass
class Part:
    """Faces, edges and where they came from."""

    faces: list[Face]
    edges: list[Edge] = field(default_factory=list)
    source: str = ""
    shape: Any = None  # OCP TopoDS_Shape when read from STEP; None for geomdl input
    warnings: list[str] = field(default_factory=list)
    #: faults of the file that change no face (:mod:`cad_io.damage`), one line each
    notes: list[str] = field(default_factory=list)
    #: True where the file is damaged (faces lost or changed; the first warning says how)
    damaged: bool = False

    @property
    def bbox(self) -> tuple[float, float, float, float, float, float]:
        b = np.array([f.bbox for f in self.faces], dtype=np.float64)
        return (*np.nanmin(b[:, :3], axis=0), *np.nanmax(b[:, 3:], axis=0))

    def __repr__(self) -> str:
        kinds: dict[str, int] = {}
        for f in self.faces:
            kinds[f.kind] = kinds.get(f.kind, 0) + 1
        return f"Part({self.source!r}, faces={len(self.faces)} {kinds}, edges={len(self.edges)})"
