"""3D distance from points to a part's B-rep: exact NURBS feet, trim-aware, mesh fallback.

:func:`distance_to_part` finds candidate faces for every point from a KD-tree
(:class:`scipy.spatial.cKDTree`) of points spread over a fine mesh of the part (each
carrying its face, its triangle and its (u, v)), projects the point onto each candidate
face's exact NURBS by damped Gauss-Newton from the nearest sample's (u, v), and keeps a
foot only where it lies inside the face's trim loops. The distance to the nearest candidate
mesh triangle is the fallback and the sanity bound: where no exact foot is within the mesh
deflection of it (the nearest point is on a trimmed boundary or an edge, or Newton stopped
in a local minimum) the mesh distance is returned, which is within the deflection of the
true one. Use a deflection well below the tolerance you check against.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .part import Part

__all__ = ["DEFLECTION", "distance_to_part", "faces_compound", "occ_distance", "occ_distance_own_tolerance",
           "occ_band_distance", "confirm_with_occ"]

#: default mesh deflection, mm: bounds the error where the mesh answers
DEFLECTION = 0.002
#: nearest KD-tree samples per point (candidate faces and triangles)
NEIGHBOURS = 32
#: finest spacing (mm) of the samples spread over the mesh
SPACING = 0.15
#: most samples spread over the mesh (the sample spacing grows to stay below it)
MAX_SAMPLES = 3_000_000


def _lattice(n: int, m: int) -> np.ndarray:
    """Barycentric weights (k, 3) of a lattice on a triangle ``n`` steps along its base, ``m`` up.

    Row ``j`` (``t = j / m`` of the way from the base A-B to the apex C) holds
    ``ceil((1 - t) * n) + 1`` points evenly spaced, so the count grows with the area,
    ``~ n * m / 2``, not with the square of the longest edge.
    """
    rows = []
    for j in range(m + 1):
        t = j / m
        k = math.ceil((1.0 - t) * n - 1e-9)
        s = np.linspace(0.0, 1.0, k + 1) if k > 0 else np.zeros(1)
        rows.append(np.c_[(1.0 - t) * (1.0 - s), (1.0 - t) * s, np.full(len(s), t)])
    return np.concatenate(rows)


def _spread(nodes: np.ndarray, uv: np.ndarray, tris: np.ndarray, spacing: float) -> tuple[np.ndarray, ...]:
    """Points on every triangle at most about ``spacing`` apart: xyz, uv and triangle index.

    Each triangle gets a lattice ``n`` steps along its longest edge and ``m`` steps across
    (its height over that edge). A lattice of ``n`` steps both ways would give a long
    sliver ``~ n^2 / 2`` points: cylinders meshed at 0.5 um are such slivers, and
    bug27453_165-174_piattello then took 183 M samples (14.7 GB) for 3 M wanted.
    """
    a, b, c = nodes[tris[:, 0]], nodes[tris[:, 1]], nodes[tris[:, 2]]
    lens = np.stack([np.linalg.norm(b - a, axis=1), np.linalg.norm(c - b, axis=1), np.linalg.norm(a - c, axis=1)])
    longest = np.argmax(lens, axis=0)
    # vertices reordered so that edge 0-1 is the longest (the base) and 2 the apex
    order = np.array([[0, 1, 2], [1, 2, 0], [2, 0, 1]])[longest]
    t3 = np.take_along_axis(tris, order, axis=1)
    base = lens[longest, np.arange(len(tris))]
    area2 = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    height = np.divide(area2, base, out=np.zeros_like(area2), where=base > 0)
    n = np.clip(np.ceil(base / spacing), 1, 200).astype(np.int64)
    m = np.clip(np.ceil(height / spacing), 1, 200).astype(np.int64)
    group = n * 256 + m
    xyz_l, uv_l, tri_l = [], [], []
    for g in np.unique(group):
        sel = np.flatnonzero(group == g)
        w = _lattice(int(g // 256), int(g % 256))
        t = t3[sel]
        xyz_l.append(np.einsum("kc,tcd->tkd", w, nodes[t]).reshape(-1, 3))
        uv_l.append(np.einsum("kc,tcd->tkd", w, uv[t]).reshape(-1, 2))
        tri_l.append(np.repeat(sel, len(w)))
    return np.concatenate(xyz_l), np.concatenate(uv_l), np.concatenate(tri_l)


class _Index:
    """KD-tree of samples over the part's fine mesh, with the packed faces it came from."""

    def __init__(self, part: Part, deflection: float):
        from scipy.spatial import cKDTree

        from .sampler import _cached_face_set

        fs = _cached_face_set(part, deflection, "+z")
        if fs.tris is None:
            raise ValueError(f"part {part.source!r} has no meshed faces to measure distances to")
        self.fs = fs
        self.deflection = deflection
        nodes, tris = fs.nodes, fs.tris
        area = 0.5 * np.linalg.norm(np.cross(nodes[tris[:, 1]] - nodes[tris[:, 0]],
                                             nodes[tris[:, 2]] - nodes[tris[:, 0]]), axis=1).sum()
        spacing = max(SPACING, math.sqrt(2.0 * area / MAX_SAMPLES))
        xyz, uv, tri = _spread(nodes, fs.uv, tris, spacing)
        face = fs.tri_face[tri]
        # one sample per face and cell of half the spacing: a densely meshed face (or nodes
        # shared by many triangles) would otherwise fill a point's nearest neighbours and
        # crowd out the face that is truly nearest (seen on the pocket's corner tori)
        key = np.ascontiguousarray(np.c_[face, np.floor(xyz / (0.5 * spacing))].astype(np.int64))
        _, first = np.unique(key.view(np.dtype((np.void, key.dtype.itemsize * 4))).ravel(), return_index=True)
        self.xyz, self.uv, self.tri, self.face = xyz[first], uv[first], tri[first], face[first]
        self.tree = cKDTree(self.xyz)
        self.spacing = spacing


def _index(part: Part, deflection: float) -> _Index:
    cache = part.__dict__.setdefault("_distance_cache", {})
    key = float(deflection)
    mesh_ids = tuple(id(f.mesh) for f in part.faces)
    hit = cache.get(key)
    if hit is not None and hit[0] == mesh_ids:
        return hit[1]
    idx = _Index(part, deflection)
    cache.clear()  # one index per part: they are large
    cache[key] = (tuple(id(f.mesh) for f in part.faces), idx)
    return idx


def distance_to_part(part: Part, points: Any, *, deflection: float | None = None,
                     neighbours: int = NEIGHBOURS, return_exact: bool = False):
    """Distance in mm from each point to the part's surface (its trimmed faces).

    Parameters
    ----------
    part : cad_io.Part
        Meshed at ``deflection`` on first use (the index is cached on the part).
    points : array_like of shape (n, 3), float
        World points in mm. Rows with NaN give NaN.
    deflection : float, optional
        Mesh deflection in mm, default :data:`DEFLECTION` (0.002). Where no exact foot is
        found (nearest point on a face boundary or edge) the answer is the distance to the
        mesh, within about this much of the exact one.
    neighbours : int
        Nearest mesh samples that nominate candidate faces and triangles.
    return_exact : bool
        Also return a bool array: True where an exact NURBS foot gave the answer.

    Returns
    -------
    ndarray of shape (n,), float64
        Distances in mm (and the ``exact`` flags when ``return_exact``).

    Examples
    --------
    >>> from pathlib import Path
    >>> import cad_io
    >>> part = cad_io.read_step(Path(cad_io.__file__).parents[1] / "data" / "pocket.step")
    >>> distance_to_part(part, [[0.0, 0.0, 16.0], [0.0, 0.0, 35.0]]).round(9).tolist()
    [1.0, 20.0]
    """
    from . import _sample_kernels as K

    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must have shape (n, 3), got {pts.shape}")
    deflection = DEFLECTION if deflection is None else float(deflection)
    if not (math.isfinite(deflection) and deflection > 0):
        raise ValueError(f"deflection must be positive, got {deflection!r}")
    neighbours = int(neighbours)
    if neighbours < 1:
        raise ValueError(f"neighbours must be at least 1, got {neighbours}")
    n = len(pts)
    out = np.full(n, np.nan)
    exact = np.zeros(n, dtype=bool)
    good = np.flatnonzero(np.isfinite(pts).all(axis=1))
    if good.size == 0:
        return (out, exact) if return_exact else out
    idx = _index(part, deflection)
    fs = idx.fs
    P = np.ascontiguousarray(pts[good])
    kq = min(neighbours, len(idx.xyz))
    _, nb = idx.tree.query(P, k=kq, workers=-1)
    nb = nb.reshape(len(P), kq)

    # mesh distance over the candidate triangles
    dmesh = np.empty(len(P))
    K.mesh_distance(P, np.ascontiguousarray(idx.tri[nb]), fs.nodes, fs.tris, dmesh)

    # candidate (point, face): the nearest sample of each face among the neighbours
    faces = idx.face[nb]  # (m, k), nearest first
    pt = np.repeat(np.arange(len(P)), kq)
    key = pt * (int(faces.max()) + 1) + faces.ravel()
    _, first = np.unique(key, return_index=True)  # first occurrence = nearest sample of that face
    cand_pt = pt[first]
    cand_face = faces.ravel()[first]
    cand_uv = idx.uv[nb.ravel()[first]]
    has_surface = fs.face_mode[cand_face] == 1
    cand_pt, cand_face, cand_uv = cand_pt[has_surface], cand_face[has_surface], cand_uv[has_surface]
    pk = fs.packed
    dc = np.empty(len(cand_pt))
    inside = np.empty(len(cand_pt), dtype=np.bool_)
    K.project_candidates(P, np.ascontiguousarray(cand_pt), np.ascontiguousarray(cand_face),
                         np.ascontiguousarray(cand_uv), pk.deg, pk.ncp, pk.koff, pk.poff, pk.knots, pk.cpw,
                         np.ascontiguousarray(np.nan_to_num(pk.domain)), *fs.trim, dc, inside)
    dexact = np.full(len(P), np.inf)
    np.minimum.at(dexact, cand_pt[inside], dc[inside])
    # an exact foot counts where it is consistent with the mesh (within its deflection)
    slack = 1.5 * max(deflection, float(np.max(fs.face_zgap[fs.face_mode == 1], initial=0.0)) / 20.0)
    use = dexact <= dmesh + slack
    res = np.where(use, dexact, dmesh)
    out[good] = res
    exact[good] = use
    return (out, exact) if return_exact else out


def faces_compound(shape: Any) -> Any:
    """A compound of the faces of an OCP shape: distances to it are to the faces, not the
    solid (a point inside a solid is at 0 from the solid)."""
    from OCP.BRep import BRep_Builder
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS_Compound

    comp = TopoDS_Compound()
    builder = BRep_Builder()
    builder.MakeCompound(comp)
    ex = TopExp_Explorer(shape, TopAbs_FACE)
    while ex.More():
        builder.Add(comp, ex.Current())
        ex.Next()
    return comp


def occ_distance(shape: Any, points: Any) -> np.ndarray:
    """Exact distance from each point to the faces of an OCP shape (BRepExtrema_DistShapeShape).

    Measured to the faces, not the solid (a point inside a solid is at 0 from it). About a
    millisecond a point: the reference for checks, not for 10^5 points.
    """
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeVertex
    from OCP.BRepExtrema import BRepExtrema_DistShapeShape
    from OCP.gp import gp_Pnt

    comp = faces_compound(shape)
    out = []
    for p in np.asarray(points, dtype=np.float64).reshape(-1, 3):
        v = BRepBuilderAPI_MakeVertex(gp_Pnt(*map(float, p))).Vertex()
        out.append(BRepExtrema_DistShapeShape(v, comp).Value())
    return np.array(out, dtype=np.float64)


def occ_distance_own_tolerance(shape: Any, points: Any) -> tuple[np.ndarray, np.ndarray]:
    """OCC's exact distance from each point to the faces of ``shape`` (as :func:`occ_distance`)
    and the tolerance, as the file gives it, of the nearest sub-shape (the face, or the edge or
    vertex of its boundary that the nearest point lies on).

    A shape is valid within its tolerances: a face reaches as far as its edges' tolerance
    beyond their curves, and OCC's ray cast (``IntCurvesFace_Intersector``) answers there, as
    the sampler does. ``max(dist - tolerance, 0)`` is the distance to the shape so toleranced.

    Examples
    --------
    >>> from pathlib import Path
    >>> import cad_io
    >>> part = cad_io.read_step(Path(cad_io.__file__).parents[1] / "data" / "pocket.step")
    >>> d, t = occ_distance_own_tolerance(part.shape, [[0.0, 0.0, 16.0]])
    >>> round(float(d[0]), 9), bool(t[0] < 1e-3)
    (1.0, True)
    """
    from OCP.BRep import BRep_Tool
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeVertex
    from OCP.BRepExtrema import BRepExtrema_DistShapeShape
    from OCP.gp import gp_Pnt
    from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE, TopAbs_VERTEX
    from OCP.TopoDS import TopoDS

    comp = faces_compound(shape)
    tol_of = {TopAbs_EDGE: lambda s: BRep_Tool.Tolerance_s(TopoDS.Edge_s(s)),
              TopAbs_VERTEX: lambda s: BRep_Tool.Tolerance_s(TopoDS.Vertex_s(s)),
              TopAbs_FACE: lambda s: BRep_Tool.Tolerance_s(TopoDS.Face_s(s))}
    dist, tol = [], []
    for p in np.asarray(points, dtype=np.float64).reshape(-1, 3):
        v = BRepBuilderAPI_MakeVertex(gp_Pnt(*map(float, p))).Vertex()
        d = BRepExtrema_DistShapeShape(v, comp)
        dist.append(d.Value())
        t = 0.0
        for k in range(1, d.NbSolution() + 1):  # the largest over equally near supports
            s = d.SupportOnShape2(k)
            f = tol_of.get(s.ShapeType())
            t = max(t, f(s) if f is not None else 0.0)
        tol.append(t)
    return np.array(dist, dtype=np.float64), np.array(tol, dtype=np.float64)


def occ_band_distance(shape: Any, points: Any, within: Any) -> tuple[np.ndarray, np.ndarray]:
    """Distance from each point to the faces of ``shape`` as OCC's ray cast sees them: each
    face's surface over its trimmed region and a band beyond it as wide as the largest
    tolerance of the face's edges in the file.

    ``IntCurvesFace_Intersector`` (OCC's ray cast) classifies a hit on a face's surface with
    that tolerance, and the sampler does the same (:attr:`cad_io.part.Face.tolerance`), so on a
    badly toleranced file the top-most surface they give runs on past a face's trim curve,
    up to 0.3 mm on trj8. :func:`occ_distance_own_tolerance` credits a point only with the
    tolerance of the sub-shape nearest it, which there can be another face or a tighter
    edge of the same face. Here each face whose box, grown by its band and ``within``,
    holds the point is tried: the point's orthogonal projection onto the face's surface
    (``GeomAPI_ProjectPointOnSurf``) counts where OCC puts that foot within the band of the
    trimmed face (``BRepExtrema_DistShapeShape``). Only that one foot per face is tried, so
    the result is an upper bound of the distance to the banded faces.

    Parameters
    ----------
    shape : OCP shape
        The part's B-rep (in the frame of the points).
    points : array_like, (n, 3)
    within : array_like, (n,) or scalar
        Only faces nearer than this (mm) are tried, per point (pass the distance already known).

    Returns
    -------
    (ndarray, ndarray)
        The distance (``inf`` where no face's band is within reach) and the band width of the
        face that gave it (0 where none).

    Examples
    --------
    >>> from pathlib import Path
    >>> import cad_io
    >>> part = cad_io.read_step(Path(cad_io.__file__).parents[1] / "data" / "pocket.step")
    >>> d, t = occ_band_distance(part.shape, [[0.0, 0.0, 16.0]], 2.0)
    >>> round(float(d[0]), 9), bool(t[0] < 1e-3)
    (1.0, True)
    """
    from OCP.BRep import BRep_Tool
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeVertex
    from OCP.BRepExtrema import BRepExtrema_DistShapeShape
    from OCP.GeomAPI import GeomAPI_ProjectPointOnSurf
    from OCP.gp import gp_Pnt
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopExp import TopExp
    from OCP.TopoDS import TopoDS
    from OCP.TopTools import TopTools_IndexedMapOfShape

    from .step import _bbox, _edge_tolerance

    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    reach = np.broadcast_to(np.asarray(within, dtype=np.float64), (len(pts),))
    fmap = TopTools_IndexedMapOfShape()
    TopExp.MapShapes_s(shape, TopAbs_FACE, fmap)
    faces = [TopoDS.Face_s(fmap.FindKey(i)) for i in range(1, fmap.Extent() + 1)]
    boxes = np.array([_bbox(f) for f in faces]).reshape(-1, 6)  # NaN for a void box: never near
    lo, hi = boxes[:, :3], boxes[:, 3:]
    band = np.array([_edge_tolerance(f) for f in faces])
    surfaces: dict[int, Any] = {}
    dist = np.full(len(pts), np.inf)
    width = np.zeros(len(pts))
    for k, p in enumerate(pts):
        grow = (band + reach[k])[:, None]
        near = np.flatnonzero(np.all((p >= lo - grow) & (p <= hi + grow), axis=1))
        for f in near:
            if f not in surfaces:
                surfaces[f] = BRep_Tool.Surface_s(faces[f])
            proj = GeomAPI_ProjectPointOnSurf(gp_Pnt(*map(float, p)), surfaces[f])
            if proj.NbPoints() == 0 or proj.LowerDistance() >= min(dist[k], reach[k]):
                continue
            foot = BRepBuilderAPI_MakeVertex(proj.NearestPoint()).Vertex()
            if BRepExtrema_DistShapeShape(foot, faces[f]).Value() <= band[f]:
                dist[k], width[k] = proj.LowerDistance(), band[f]
    return dist, width


def confirm_with_occ(part: Part, points: Any, dist: np.ndarray, *, above: float, slack: Any = 0.0,
                     max_points: int = 2000) -> tuple[np.ndarray, int, int]:
    """Replace the largest distances above ``above`` by OCC's exact ones.

    :func:`distance_to_part` can over-report where no candidate face's exact foot is found
    (it then measures to a farther face or the mesh). A report's maximum must not rest on
    that, so the points above the threshold, largest first, up to ``max_points``, are
    measured again with :func:`occ_distance`.

    ``slack`` (mm, scalar or per point) is how far a distance may under-report: a point
    counts as above the threshold where ``dist + slack > above``. Pass the mesh deflection
    where :func:`distance_to_part` answered from the mesh (``return_exact``) and 0 where
    from an exact foot (which never under-reports), and every point truly farther than
    ``above`` is measured by OCC, whatever the deflection.

    Examples
    --------
    >>> from pathlib import Path
    >>> import cad_io
    >>> part = cad_io.read_step(Path(cad_io.__file__).parents[1] / "data" / "pocket.step")
    >>> d, n_occ, n_left = confirm_with_occ(part, [[0.0, 0.0, 16.0], [0.0, 0.0, 15.0]], [0.9, 0.0],
    ...                                     above=0.5)
    >>> d.round(9).tolist(), n_occ, n_left
    ([1.0, 0.0], 1, 0)

    Returns
    -------
    dist : ndarray
        A copy with the confirmed points replaced.
    n_checked : int
        Points measured by OCC.
    n_left : int
        Points above the threshold left unchecked (``max_points`` reached).
    """
    dist = np.array(dist, dtype=np.float64, copy=True)
    upper = np.nan_to_num(dist + np.broadcast_to(np.asarray(slack, dtype=np.float64), dist.shape), nan=-np.inf)
    if part.shape is None:
        return dist, 0, int(np.sum(upper > above))
    over = np.flatnonzero(upper > above)
    over = over[np.argsort(-upper[over], kind="stable")]
    check = over[:max_points]
    if check.size:
        dist[check] = occ_distance(part.shape, np.asarray(points, dtype=np.float64)[check])
    return dist, int(check.size), int(over.size - check.size)
