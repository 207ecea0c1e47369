"""Triangle meshes of a part's faces, with each node's (u, v) on the face's NURBS.

:func:`triangulate` meshes a STEP part with OpenCASCADE's ``BRepMesh_IncrementalMesh`` (on
``Part.shape``, so neighbouring faces share their edge nodes) and a geomdl part on a
regular (u, v) grid refined until it is within the deflection. The facet path of the
sampler rasterises these triangles; the (u, v) let it polish facet heights with Newton.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from cad_io.part import Face, FaceMesh, Part

__all__ = ["ANGULAR_DEFLECTION", "mesh_faces_alone", "triangulate", "trimmed_grid_mesh"]

#: Angular deflection (radians) passed to BRepMesh beside the linear one.
ANGULAR_DEFLECTION = 0.35
#: BRepMesh is asked for this share of the deflection: its own measure of the chordal
#: error samples few points, and a torus meshed at d comes out up to ~1.1 d off.
_OCC_SHARE = 0.75
#: Largest distance (mm) accepted between a mesh node and the NURBS at its (u, v).
_UV_TOL = 1e-7


def triangulate(part: Part, deflection: float) -> None:
    """Mesh every face of ``part`` in place: sets ``face.mesh`` to a :class:`FaceMesh`.

    Parameters
    ----------
    part : Part
        From :func:`cad_io.read_step` (meshed with BRepMesh on ``part.shape``) or
        :func:`cad_io.from_geomdl` (meshed on a (u, v) grid).
    deflection : float
        Largest distance in mm between a triangle and its surface (chordal deflection).

    Notes
    -----
    ``FaceMesh.nodes`` are world coordinates (mm), ``triangles`` (m, 3) int32 indices
    ordered so that their right-hand normals point out of the face (the face's orientation
    is applied), ``uv`` the parameters of each node on ``face.surface`` (None where the
    face has no surface, e.g. tessellated-only STEP faces, whose stored triangles are used
    as they are).

    Examples
    --------
    >>> import cad_io  # doctest: +SKIP
    >>> part = cad_io.read_step("part.step")  # doctest: +SKIP
    >>> triangulate(part, 0.01)  # doctest: +SKIP
    >>> part.faces[0].mesh.triangles.shape  # doctest: +SKIP
    (412, 3)
    """
    deflection = float(deflection)
    if not deflection > 0 or not np.isfinite(deflection):
        raise ValueError(f"deflection must be a positive number of mm, got {deflection!r}")
    if part.shape is None:
        for face in part.faces:
            face.mesh = _grid_mesh(face, deflection) if face.surface is not None else None
        return
    _occ_meshes(part, deflection)
    # a face whose surface spikes far beyond its edges (a damaged control point) is left out
    from cad_io.damage import refuse_runaway_meshes

    refuse_runaway_meshes(part)


# --------------------------------------------------------------------------------------
# OpenCASCADE


def _occ_meshes(part: Part, deflection: float) -> None:
    from OCP.BRep import BRep_Tool
    from OCP.BRepMesh import BRepMesh_IncrementalMesh
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopExp import TopExp
    from OCP.TopoDS import TopoDS
    from OCP.TopTools import TopTools_IndexedMapOfShape

    fmap = TopTools_IndexedMapOfShape()
    TopExp.MapShapes_s(part.shape, TopAbs_FACE, fmap)
    if fmap.Extent() != len(part.faces):
        raise ValueError(f"part.shape has {fmap.Extent()} faces but the part lists "
                         f"{len(part.faces)}")
    has_surface = any(BRep_Tool.Surface_s(TopoDS.Face_s(fmap.FindKey(i))) is not None
                      for i in range(1, fmap.Extent() + 1))
    if has_surface:
        from OCP.BRepTools import BRepTools

        # OCC keeps a finer triangulation made before and would hand it back: the mesh at a
        # deflection must not depend on what was meshed earlier (the height sampler's fine
        # meshes carry slivers that the access lattice samples badly)
        BRepTools.Clean_s(part.shape)
        BRepMesh_IncrementalMesh(part.shape, _OCC_SHARE * deflection, False, ANGULAR_DEFLECTION,
                                 True)
    for face in part.faces:
        f = TopoDS.Face_s(fmap.FindKey(face.index + 1))
        face.mesh = _occ_face_mesh(face, f, f, deflection)


def _occ_face_mesh(face: Face, f: Any, whole: Any, deflection: float) -> FaceMesh | None:
    """The :class:`FaceMesh` of ``face`` from the triangulation of the OCC face ``f``: the
    part's own face ``whole`` or a copy of it (same surface and parameters); None where
    ``f`` has no triangles."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepTools import BRepTools
    from OCP.TopAbs import TopAbs_REVERSED
    from OCP.TopLoc import TopLoc_Location

    loc = TopLoc_Location()
    tri = BRep_Tool.Triangulation_s(f, loc)
    if tri is None or tri.NbTriangles() == 0:
        return None
    nodes = np.array([tri.Node(i).Coord() for i in range(1, tri.NbNodes() + 1)])
    if not loc.IsIdentity():
        t = loc.Transformation()
        m = np.array([[t.Value(r, c) for c in range(1, 5)] for r in range(1, 4)])
        nodes = nodes @ m[:, :3].T + m[:, 3]
    triangles = np.array([tri.Triangle(i).Get() for i in range(1, tri.NbTriangles() + 1)],
                         dtype=np.int32) - 1
    if f.Orientation() == TopAbs_REVERSED:
        triangles = triangles[:, [0, 2, 1]]
    uv = None
    if face.surface is not None and tri.HasUVNodes():
        uv0 = np.array([tri.UVNode(i).Coord() for i in range(1, tri.NbNodes() + 1)])
        if face.topo is not None and not face.topo.IsSame(whole):
            # converted face: map the original parameters onto the NURBS ones
            uv0 = _rescale(uv0, BRepTools.UVBounds_s(whole), BRepTools.UVBounds_s(face.topo))
        uv = _fit_uv(face, nodes, uv0)
    return FaceMesh(nodes=nodes, triangles=np.ascontiguousarray(triangles), uv=uv, deflection=deflection)


def mesh_faces_alone(part: Part, faces: Sequence[int], deflection: float) -> list:
    """Meshes at ``deflection`` of ``part``'s faces ``faces``, each meshed alone on a copy.

    A face meshed alone has the same triangles whichever other faces are wanted (BRepMesh on
    a compound of faces discretises their shared edges once, for all of them), and the
    part's own OCC triangulation is left as it is (a fine mesh made on the part's faces
    would stay attached to them for as long as the part lives). A face without a surface
    (tessellated only) keeps its current mesh.

    Returns
    -------
    list of FaceMesh or None
        One per entry of ``faces``: None where the face gets no triangles.
    """
    from OCP.BRep import BRep_Tool
    from OCP.BRepBuilderAPI import BRepBuilderAPI_Copy
    from OCP.BRepMesh import BRepMesh_IncrementalMesh
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopExp import TopExp
    from OCP.TopoDS import TopoDS
    from OCP.TopTools import TopTools_IndexedMapOfShape

    if part.shape is None:
        raise ValueError(f"part {part.source!r} has no OCC shape to mesh")
    fmap = TopTools_IndexedMapOfShape()
    TopExp.MapShapes_s(part.shape, TopAbs_FACE, fmap)
    out = []
    for k in faces:
        f = TopoDS.Face_s(fmap.FindKey(int(k) + 1))
        if BRep_Tool.Surface_s(f) is None:
            # a tessellated-only face: its stored triangles are all there is (a copy drops them)
            out.append(part.faces[int(k)].mesh)
            continue
        copy = TopoDS.Face_s(BRepBuilderAPI_Copy(f).Shape())
        BRepMesh_IncrementalMesh(copy, _OCC_SHARE * deflection, False, ANGULAR_DEFLECTION, True)
        out.append(_occ_face_mesh(part.faces[int(k)], copy, f, deflection))
    return out


def _rescale(uv: np.ndarray, src, dst) -> np.ndarray:
    """Map (u, v) linearly from the box ``src`` (u0, u1, v0, v1) onto ``dst``."""
    out = np.empty_like(uv)
    for c, (a0, a1, b0, b1) in enumerate(((src[0], src[1], dst[0], dst[1]),
                                          (src[2], src[3], dst[2], dst[3]))):
        span = a1 - a0
        out[:, c] = b0 + (uv[:, c] - a0) * ((b1 - b0) / span if span != 0 else 0.0)
    return out


def _fit_uv(face: Face, nodes: np.ndarray, uv0: np.ndarray) -> np.ndarray:
    """(u, v) on ``face.surface`` of mesh nodes, polished by Gauss-Newton from ``uv0``."""
    from cad_io._nurbs_kernels import project_points
    from cad_io.nurbs import pack

    pk = pack([face.surface])
    uv = np.empty_like(uv0)
    dist = np.empty(len(uv0))
    project_points(*pk.arrays(), 0, np.ascontiguousarray(nodes),
                   np.ascontiguousarray(uv0), _UV_TOL, uv, dist)
    return uv


# --------------------------------------------------------------------------------------
# regular (u, v) grids for geomdl faces


def _grid(face: Face, n_u: int, n_v: int):
    from cad_io.nurbs import evaluate

    u0, u1, v0, v1 = face.surface.domain
    u = np.linspace(u0, u1, n_u)
    v = np.linspace(v0, v1, n_v)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    return uu, vv, evaluate(face.surface, uu, vv)[..., 0, :]


def _grid_error(face: Face, uu, vv, pts) -> float:
    """Largest distance between the surface and the grid's triangles at edge midpoints."""
    from cad_io.nurbs import evaluate

    s = face.surface
    errs = []
    # u-edges, v-edges and the cell diagonals (i, j)-(i+1, j+1)
    for a, b in (((slice(None, -1), slice(None)), (slice(1, None), slice(None))),
                 ((slice(None), slice(None, -1)), (slice(None), slice(1, None))),
                 ((slice(None, -1), slice(None, -1)), (slice(1, None), slice(1, None)))):
        um = 0.5 * (uu[a] + uu[b])
        vm = 0.5 * (vv[a] + vv[b])
        lin = 0.5 * (pts[a] + pts[b])
        errs.append(np.max(np.linalg.norm(evaluate(s, um, vm)[..., 0, :] - lin, axis=-1)))
    return float(max(errs))


def _refined_grid(face: Face, deflection: float, max_nodes: int):
    """A regular (u, v) grid over ``face.surface``'s domain, refined until its triangles are
    within ``deflection`` or it has more than ``max_nodes`` nodes: ``(uu, vv, pts, error)``."""
    s = face.surface
    nu, nv = s.poles.shape[:2]
    n_u = max(2, 2 * (nu - s.degree_u) + 1) if s.degree_u > 1 else nu
    n_v = max(2, 2 * (nv - s.degree_v) + 1) if s.degree_v > 1 else nv
    n_u, n_v = max(n_u, len(np.unique(s.knots_u))), max(n_v, len(np.unique(s.knots_v)))
    while True:
        uu, vv, pts = _grid(face, n_u, n_v)
        err = _grid_error(face, uu, vv, pts)
        if err <= deflection or n_u * n_v > max_nodes:
            return uu, vv, pts, err
        # chordal error falls with the square of the step
        grow = min(8.0, max(1.5, np.sqrt(err / deflection) * 1.1))
        n_u = int(np.ceil((n_u - 1) * grow)) + 1 if s.degree_u > 1 or s.rational else n_u
        n_v = int(np.ceil((n_v - 1) * grow)) + 1 if s.degree_v > 1 or s.rational else n_v
        if s.degree_u == 1 and s.degree_v == 1 and not s.rational:
            n_u = int(np.ceil((n_u - 1) * grow)) + 1  # bilinear patches: twisted cells
            n_v = int(np.ceil((n_v - 1) * grow)) + 1


def _cell_triangles(a, b, c, d, reversed_: bool) -> np.ndarray:
    """Two triangles per grid cell with corners ``a`` (i, j), ``b`` (i+1, j), ``c`` (i+1, j+1),
    ``d`` (i, j+1), turned where the face is reversed."""
    tris = np.concatenate([np.c_[a, b, c], np.c_[a, c, d]]).astype(np.int32)
    return np.ascontiguousarray(tris[:, [0, 2, 1]] if reversed_ else tris)


def _grid_mesh(face: Face, deflection: float) -> FaceMesh:
    uu, vv, pts, _err = _refined_grid(face, deflection, 4_000_000)
    idx = np.arange(uu.size, dtype=np.int32).reshape(uu.shape)
    tris = _cell_triangles(idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel(),
                           face.reversed)
    return FaceMesh(nodes=pts.reshape(-1, 3), triangles=tris,
                    uv=np.c_[uu.ravel(), vv.ravel()], deflection=deflection)


def trimmed_grid_mesh(face: Face, deflection: float, reach: float, *, max_nodes: int = 262_144) -> FaceMesh:
    """A regular (u, v) grid mesh of a trimmed face, kept where the face is and ``reach`` beyond.

    For faces that BRepMesh does not mesh to the deflection asked (faces whose edges carry a
    large tolerance: trj8's, 0.4-0.6 mm off their surface at a requested 10 um), the
    sampler's Newton starts and facet fallback come from this grid instead: nodes exactly
    on the surface, refined as :func:`_grid_mesh` until within ``deflection`` (or
    ``max_nodes``), and only the cells over the trimmed region, grown by rings of cells
    until they reach at least ``reach`` mm (3D) beyond it.

    Parameters
    ----------
    face : Face
        With a ``surface`` and its trim ``loops`` in the surface's (u, v).
    deflection : float
        Chordal error (mm) the grid is refined to.
    reach : float
        How far (mm) beyond the trim loops the kept cells must go (the edges' tolerance
        band plus the boundary margin).
    max_nodes : int
        Largest grid refined to; a face that needs more keeps the error it reached.

    Returns
    -------
    FaceMesh
        ``deflection`` is the error the grid has (may exceed the one asked for).
    """
    from cad_io import _sample_kernels as K
    from scipy.ndimage import binary_dilation

    uu, vv, pts, err = _refined_grid(face, deflection, max_nodes)
    n_u, n_v = uu.shape
    loops = [np.asarray(lp, dtype=np.float64).reshape(-1, 2) for lp in face.loops]
    loops = [lp for lp in loops if len(lp) >= 3]
    if loops:
        loop_uv = np.ascontiguousarray(np.concatenate(loops))
        loop_off = np.concatenate([[0], np.cumsum([len(lp) for lp in loops])]).astype(np.int64)
        inside = np.empty(uu.size, dtype=np.bool_)
        K.points_in_loops(np.ascontiguousarray(uu.ravel()), np.ascontiguousarray(vv.ravel()), loop_uv, loop_off,
                          0.0, inside)
        inside = inside.reshape(n_u, n_v)
        cells = inside[:-1, :-1] | inside[1:, :-1] | inside[1:, 1:] | inside[:-1, 1:]
        # a loop vertex marks its cell: a trimmed sliver between two grid nodes
        u0, u1, v0, v1 = uu[0, 0], uu[-1, 0], vv[0, 0], vv[0, -1]
        iu = np.clip(((loop_uv[:, 0] - u0) / max(u1 - u0, 1e-300) * (n_u - 1)).astype(np.int64), 0, n_u - 2)
        iv = np.clip(((loop_uv[:, 1] - v0) / max(v1 - v0, 1e-300) * (n_v - 1)).astype(np.int64), 0, n_v - 2)
        cells[iu, iv] = True
        # rings of cells until ``reach``: by the shortest grid step over the face's cells
        du = np.linalg.norm(np.diff(pts, axis=0), axis=-1)
        dv = np.linalg.norm(np.diff(pts, axis=1), axis=-1)
        steps = np.concatenate([du.ravel(), dv.ravel()])
        steps = steps[steps > 1e-9]
        step = float(steps.min()) if steps.size else 0.0
        rings = max(n_u, n_v) if step <= 0 else min(max(n_u, n_v), int(np.ceil(reach / step)) + 1)
        cells = binary_dilation(cells, structure=np.ones((3, 3), dtype=bool), iterations=rings)
    else:
        cells = np.ones((n_u - 1, n_v - 1), dtype=np.bool_)
    used = np.zeros((n_u, n_v), dtype=np.bool_)
    used[:-1, :-1] |= cells
    used[1:, :-1] |= cells
    used[1:, 1:] |= cells
    used[:-1, 1:] |= cells
    idx = np.full((n_u, n_v), -1, dtype=np.int64)
    idx[used] = np.arange(int(used.sum()))
    tris = _cell_triangles(idx[:-1, :-1][cells], idx[1:, :-1][cells], idx[1:, 1:][cells], idx[:-1, 1:][cells],
                           face.reversed)
    return FaceMesh(nodes=np.ascontiguousarray(pts[used]), triangles=tris,
                    uv=np.c_[uu[used], vv[used]], deflection=float(max(err, 0.0)))
