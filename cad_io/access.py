"""Tool access directions of a part (paper 002): its exact faces voxelised, and an OCC truth.

:func:`surface_samples` samples every trimmed face at a step d': each triangle of the face's
mesh (its (u, v) stay inside the trim loops) is split into n^2 sub-triangles in (u, v), and the
exact NURBS (:mod:`cad_io.nurbs`, the evaluator the z-map sampler uses) gives the point, the
outward normal and the principal curvatures at each sub-triangle's centroid. Faces with only
triangles (AP242 tessellated) are sampled on their triangles, flat. :func:`voxelize` folds the
samples into a :class:`zmap.access.VoxelMap`; :func:`analyse` runs the whole pipeline.

The reference shares no code with that pipeline: :func:`reference_visibility` casts one OCC
ray per (point, direction) (``IntCurvesFace_ShapeIntersector``) and
:func:`reference_tool` measures with ``BRepExtrema_DistShapeShape`` the distance from the
part to the ball-end tool's axis (ball centre to shank top) and to the holder's axis.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from cad_io.distance import faces_compound
from cad_io.part import Part
from zmap.access.pipeline import analyse_samples, check_args
from zmap.access.samples import Samples, largest_curvature
from zmap.access.voxelmap import AccessModelError, AccessResult, Tool, VoxelMap

__all__ = ["Samples", "surface_samples", "voxelize", "analyse", "agreement", "point_visibility", "point_access", "reference_visibility",
           "solid_rule", "top_faces",
           "reference_tool", "read_part"]


def _lattice(xyz: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sample points of triangles on a lattice of pitch ``step`` in each triangle's own frame.

    Returns ``(tri, b1, b2)``: the triangle of each sample and its barycentric weights of
    corners 1 and 2. Each triangle gets the lattice nodes inside it (its centroid when none).
    """
    a, b, c = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    e1 = b - a
    l1 = np.linalg.norm(e1, axis=1)
    ok = l1 > 0
    e1 = np.where(ok[:, None], e1 / np.maximum(l1, 1e-300)[:, None], 0.0)
    ac = c - a
    x2 = np.einsum("ij,ij->i", ac, e1)
    y2v = ac - x2[:, None] * e1
    y2 = np.linalg.norm(y2v, axis=1)
    # frame: a at (0, 0), b at (l1, 0), c at (x2, y2)
    xmin, xmax = np.minimum(0.0, x2), np.maximum(l1, x2)
    nxs = np.maximum(1, np.ceil((xmax - xmin) / step).astype(np.int64))
    nys = np.maximum(1, np.ceil(y2 / step).astype(np.int64))
    cnt = nxs * nys
    tri = np.repeat(np.arange(len(xyz)), cnt)
    local = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    ix, iy = local // nys[tri], local % nys[tri]
    px = xmin[tri] + (ix + 0.5) * (xmax - xmin)[tri] / nxs[tri]
    py = (iy + 0.5) * y2[tri] / nys[tri]
    # barycentric of (px, py) in the frame triangle
    with np.errstate(divide="ignore", invalid="ignore"):
        w2 = py / y2[tri]
        w1 = (px - w2 * x2[tri]) / l1[tri]
    keep = (w1 >= 0) & (w2 >= 0) & (w1 + w2 <= 1) & np.isfinite(w1) & np.isfinite(w2)
    tri, w1, w2 = tri[keep], w1[keep], w2[keep]
    empty = np.setdiff1d(np.arange(len(xyz)), tri)
    tri = np.concatenate([tri, empty])
    w1 = np.concatenate([w1, np.full(len(empty), 1 / 3)])
    w2 = np.concatenate([w2, np.full(len(empty), 1 / 3)])
    return tri, w1, w2


def _curvatures(der: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Largest principal curvature w.r.t. ``normal`` (positive = the surface bends toward it,
    concave seen from outside) from rows S, Su, Sv, Suu, Suv, Svv."""
    su, sv, suu, suv, svv = der[:, 1], der[:, 2], der[:, 3], der[:, 4], der[:, 5]

    def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return np.einsum("ij,ij->i", a, b)

    return largest_curvature(dot(su, su), dot(su, sv), dot(sv, sv), dot(suu, normal), dot(suv, normal),
                             dot(svv, normal))


def surface_samples(part: Part, step: float, *, deflection: float | None = None) -> Samples:
    """Samples of every face of ``part`` at spacing about ``step`` (mm).

    Raises
    ------
    AccessModelError
        When no face has an exact surface (a tessellated-only file) or the part has no faces.
    """
    from cad_io.mesh import triangulate
    from cad_io.nurbs import evaluate_packed, pack

    step = float(step)
    if not part.faces:
        raise AccessModelError(f"{part.source or 'part'}: no faces to voxelise")
    exact = [f for f in part.faces if f.surface is not None]
    if not exact:
        raise AccessModelError(f"{part.source or 'part'}: no face has an exact surface (only triangles, "
                               "as in a tessellated AP242 file): access directions need exact faces")
    deflection = float(deflection) if deflection is not None else max(step, 0.01)
    # meshed at this deflection, not reusing a mesh another step left (the sampler's finer one)
    if any(f.mesh is None or (f.surface is not None and f.mesh.deflection != deflection) for f in part.faces):
        triangulate(part, deflection)
    packed = pack([f.surface for f in part.faces])
    P, Nn, C, Fc, Wt = [], [], [], [], []
    for face in part.faces:
        m = face.mesh
        if m is None or len(m.triangles) == 0:
            continue
        tri = m.triangles
        xyz = m.nodes[tri]  # (t, 3, 3)
        area = 0.5 * np.linalg.norm(np.cross(xyz[:, 1] - xyz[:, 0], xyz[:, 2] - xyz[:, 0]), axis=1)
        tnorm = np.cross(xyz[:, 1] - xyz[:, 0], xyz[:, 2] - xyz[:, 0])
        tnorm /= np.maximum(np.linalg.norm(tnorm, axis=1), 1e-300)[:, None]
        ti, b1, b2 = _lattice(xyz, step)
        per = np.bincount(ti, minlength=len(tri))
        w = area[ti] / per[ti]
        b0 = 1.0 - b1 - b2
        if face.surface is not None and m.uv is not None:
            uv = m.uv[tri[ti]]  # (s, 3, 2)
            u = b0 * uv[:, 0, 0] + b1 * uv[:, 1, 0] + b2 * uv[:, 2, 0]
            v = b0 * uv[:, 0, 1] + b1 * uv[:, 1, 1] + b2 * uv[:, 2, 1]
            der = evaluate_packed(packed, face.index, u, v, derivs=2)
            cr = np.cross(der[:, 1], der[:, 2])
            ln = np.linalg.norm(cr, axis=1)
            scale = np.linalg.norm(der[:, 1], axis=1) * np.linalg.norm(der[:, 2], axis=1)
            good = ln > 1e-9 * np.maximum(scale, 1e-300)
            nrm = cr / np.maximum(ln, 1e-300)[:, None]
            if face.reversed:
                nrm = -nrm
            # the mesh triangles are wound outward: use them where the NURBS is singular
            nrm[~good] = tnorm[ti][~good]
            k = _curvatures(der, nrm)
            k[~good] = np.inf  # a singular point (a pole): no curvature, treated as too sharp
            pts = der[:, 0]
        else:
            pts = b0[:, None] * xyz[ti, 0] + b1[:, None] * xyz[ti, 1] + b2[:, None] * xyz[ti, 2]
            nrm = tnorm[ti]
            k = np.zeros(len(pts))
        P.append(pts)
        Nn.append(nrm)
        C.append(k)
        Fc.append(np.full(len(pts), face.index, dtype=np.int64))
        Wt.append(w)
    if not P:
        raise AccessModelError(f"{part.source or 'part'}: no face could be meshed for sampling")
    return Samples(np.concatenate(P), np.concatenate(Nn), np.concatenate(C), np.concatenate(Fc),
                   np.concatenate(Wt))


def solid_rule(part: Part, solid: str = "auto") -> tuple[str, str]:
    """The material rule for ``part`` and why (:mod:`zmap.access.solid`): ``'below'`` for an
    open model (free boundary edges: a quilt of faces with no closed shell) or where asked,
    else ``'auto'`` (a closed shell, or below where the paint leaks through it).

    Returns
    -------
    (solid, note) : the rule to pass to :meth:`VoxelMap.from_samples` and the note it shows.
    """
    from zmap.access.solid import check_solid

    solid, _ = check_solid(solid, None)
    free = sum(1 for e in part.edges if e.is_boundary)
    if solid == "below":
        return "below", "asked (--solid below)"
    if solid == "auto" and free:
        return "below", f"open model: {free} free boundary edges"
    if solid == "closed":
        return "closed", "asked (--solid closed)"
    return "auto", "no free boundary edge" if part.edges else ""


def voxelize(part: Part, d: float, *, step: float | None = None, q: int = 4, exact: bool = True,
             crease_deg: float = 10.0, check: bool = True, solid: str = "auto", floor: float | None = None,
             max_uncertain: float | None = None) -> VoxelMap:
    """The visibility voxel map of ``part`` at voxel ``d`` (mm), sampled at ``step`` (d/4).

    ``solid``: ``'auto'`` (default) the material below the top surface for an open model
    (free boundary edges), else the closed shell's paint spreading (:func:`solid_rule`);
    ``'closed'`` or ``'below'`` (down to ``floor`` or the lowest point) where asked.
    ``max_uncertain``: the largest share of uncertain boundary area (walls or gaps thinner
    than the voxel) before the map is refused (0.25).

    Examples
    --------
    >>> import cad_io  # doctest: +SKIP
    >>> vm = voxelize(cad_io.read_step("data/pocket.step"), 0.5, q=4)  # doctest: +SKIP
    """
    d, step, q = check_args(d, step, q)
    rule, note = solid_rule(part, solid)
    s = surface_samples(part, step)
    return VoxelMap.from_samples(s.points, s.normals, s.curvature, s.face, s.weight, d=d, q=q,
                                 step=step, exact=exact, crease_deg=crease_deg, check=check, solid=rule,
                                 floor=floor, max_uncertain=max_uncertain, solid_note=note)


def analyse(part: Part, *, d: float = 0.5, q: int = 4, tool: Tool, step: float | None = None,
            cone: float | None = None, exact: bool = True, rays: int = 2, refine: bool = True,
            progress=None, tool_step: float | None = None, solid: str = "auto", floor: float | None = None,
            max_uncertain: float | None = None) -> AccessResult:
    """The whole pipeline: voxel map, V'_g, A', 3-axis verdict and set-ups, with timings.

    ``rays``: lines per voxel edge of the cylinder casting (:func:`global_visibility`);
    ``refine``: cast the half-voxel pieces again where the voxel's cylinder is blocked (the
    refinement of :func:`global_visibility`; False: the paper's casting alone).
    ``tool_step``: the sampling step of the surface samples that A' tests the tool on
    (:func:`zmap.access.voxelmap.accessibility` with ``samples``), d / 2 (or d') by default (on
    featuretype.STEP the samples at d' = d / 4 gave the same agreement with OCC's tool in
    three times the time).
    ``solid``, ``floor``, ``max_uncertain``: the material rule, as :func:`voxelize`.
    ``progress(message)`` is called at each stage (the CLI prints it).
    """
    rule, note = solid_rule(part, solid)
    # one mesh for the map's samples and the tool's (at their own steps)
    deflection = max(check_args(d, step, q)[1], 0.01)
    return analyse_samples(lambda st: surface_samples(part, st, deflection=deflection), d=d, q=q, tool=tool,
                           step=step,
                           bbox=part.bbox, source=str(part.source or ""), cone=cone, exact=exact, rays=rays,
                           refine=refine, progress=progress, tool_step=tool_step, solid=rule, solid_note=note,
                           floor=floor, max_uncertain=max_uncertain)


def read_part(path) -> Part:
    """Read a STEP file for access analysis (no mesh yet)."""
    from cad_io.step import read_step

    return read_step(path)


# --------------------------------------------------------------------------------------
# the independent reference (OCC)


def reference_visibility(shape: Any, points, directions, *, offset: float = 1e-4,
                         far: float = 1e4) -> tuple[np.ndarray, np.ndarray]:
    """Thin-ray visibility by OCC: is the ray from each point along each direction free?

    Parameters
    ----------
    shape : OCP shape (or cadquery Shape)
    points : ndarray of shape (n, 3)
        Surface points; each ray starts ``offset`` mm along its direction.
    directions : ndarray of shape (k, 3)
        Unit directions.

    Returns
    -------
    free : ndarray of shape (n, k), bool
    hit : ndarray of shape (n, k), float64
        Distance to the first hit (inf where free).
    """
    from OCP.gp import gp_Dir, gp_Lin, gp_Pnt
    from OCP.IntCurvesFace import IntCurvesFace_ShapeIntersector
    from OCP.TopAbs import TopAbs_OUT

    shape = getattr(shape, "wrapped", shape)
    inter = IntCurvesFace_ShapeIntersector()
    inter.Load(faces_compound(shape), 1e-7)
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    dirs = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    hit = np.full((len(pts), len(dirs)), np.inf)
    gd = [gp_Dir(*map(float, v)) for v in dirs]
    for a, p in enumerate(pts):
        for b, v in enumerate(dirs):
            o = p + offset * v
            inter.Perform(gp_Lin(gp_Pnt(*map(float, o)), gd[b]), 0.0, far)
            if not inter.IsDone():
                continue
            best = np.inf
            for i in range(1, inter.NbPnt() + 1):
                if inter.State(i) == TopAbs_OUT:
                    continue
                w = inter.WParameter(i)
                if w < best:
                    best = w
            hit[a, b] = best + offset if np.isfinite(best) else np.inf
    return ~np.isfinite(hit), hit


def reference_tool(shape: Any, points, normals, directions, tool: Tool, *, tol: float = 1e-3,
                   reach: float = 200.0, shrink: float = 0.0, material: str = "closed") -> np.ndarray:
    """Ball-end tool clearance by OCC: (n, k) bool, True where the tool fits.

    The ball of radius a touches each point from outside (centre ``p + a n``); along direction
    t the ball and shank are the capsule of radius a around the segment from the centre to
    ``reach`` mm up, and the holder the flat-bottomed cylinder of its radius R from the
    stick-out up. The tool fits when the part keeps ``a - tol`` from the segment
    (``BRepExtrema_DistShapeShape``), no face meets the holder's cylinder shrunk by ``tol``
    (tested only where the part comes within ``R - tol`` of the holder's axis: the capsule
    around it holds the cylinder), and the ball's centre lies outside the solid.

    ``shrink``: test the shank's capsule and the holder that much thinner, and the holder's
    face that much higher (the ball stays): with a voxel diagonal, a pair blocked at 0 and
    free here is blocked within one voxel.

    ``material``: what the ball's centre must lie outside of: ``'closed'`` the solid
    (``BRepClass3d_SolidClassifier``), ``'below'`` the material below the top surface of an
    open model (a point is inside when the OCC ray from it along +z meets a face).
    """
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeVertex
    from OCP.BRepClass3d import BRepClass3d_SolidClassifier
    from OCP.BRepExtrema import BRepExtrema_DistShapeShape
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeCylinder
    from OCP.gp import gp_Ax2, gp_Dir, gp_Pnt
    from OCP.TopAbs import TopAbs_OUT

    shape = getattr(shape, "wrapped", shape)
    a = tool.radius
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    nrm = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    dirs = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    out = np.zeros((len(pts), len(dirs)), dtype=bool)
    faces = faces_compound(shape)

    def dist(p0, p1) -> float:
        if np.allclose(p0, p1):
            shp = BRepBuilderAPI_MakeVertex(gp_Pnt(*map(float, p0))).Vertex()
        else:
            shp = BRepBuilderAPI_MakeEdge(gp_Pnt(*map(float, p0)), gp_Pnt(*map(float, p1))).Edge()
        ext = BRepExtrema_DistShapeShape(faces, shp)
        return ext.Value() if ext.IsDone() else -np.inf

    def meets_cylinder(p0, t, r) -> bool:
        # a face inside the solid counts too (DistShapeShape's inner solution: distance 0)
        cyl = BRepPrimAPI_MakeCylinder(gp_Ax2(gp_Pnt(*map(float, p0)), gp_Dir(*map(float, t))), r, reach).Solid()
        ext = BRepExtrema_DistShapeShape(faces, cyl)
        return not ext.IsDone() or ext.Value() <= 0.0

    if material not in ("closed", "below"):
        raise ValueError(f"material must be 'closed' or 'below', got {material!r}")

    def inside(c) -> bool:
        if material == "below":
            return not bool(reference_visibility(shape, c[None], np.array([[0.0, 0.0, 1.0]]), offset=0.0)[0][0, 0])
        return BRepClass3d_SolidClassifier(shape, gp_Pnt(*map(float, c)), 1e-7).State() != TopAbs_OUT

    for i, (p, n) in enumerate(zip(pts, nrm)):
        c = p + a * n
        if inside(c) or dist(c, c) < a - tol:
            continue
        for j, t in enumerate(dirs):
            if dist(c, c + reach * t) < a - tol - shrink:
                continue
            if tool.holder_diameter > 0:
                h0 = c + (tool.stickout - a + shrink) * t
                rh = tool.holder_diameter / 2 - tol - shrink
                if dist(h0, h0 + reach * t) < rh and meets_cylinder(h0, t, rh):
                    continue
            out[i, j] = True
    return out


def point_visibility(result: AccessResult, voxel: np.ndarray, face: np.ndarray,
                     points: np.ndarray | None = None) -> np.ndarray:
    """``V'_g`` (n, words) that the map gives surface points of ``face`` in boundary voxels
    ``voxel``: with ``points`` (n, 3) and a refined map (``result.vg_fine``), their half-voxel
    piece's (the face's samples in the point's half-voxel cell of the voxel); else their
    face's piece's where several faces meet in the voxel (and the pieces were cast); else the
    voxel's."""
    from zmap.access.voxelmap import _octant

    vm = result.vm
    voxel = np.asarray(voxel, dtype=np.int64)
    face = np.asarray(face, dtype=np.int64)
    out = _by_piece(vm, result.vg, result.vg_pieces, voxel, face)
    f = vm.fine
    if points is None or result.vg_fine is None or f is None or not len(f.voxel) or not len(voxel):
        return out
    octant = _octant(points, vm.origin, vm.d, vm.ijk[voxel])
    nf = int(max(f.face.max(), face.max())) + 1
    keys = (f.voxel.astype(np.int64) * 8 + f.octant) * nf + f.face  # sorted (see VoxelMap.fine)
    want = (voxel * 8 + octant) * nf + face
    at = np.clip(np.searchsorted(keys, want), 0, len(keys) - 1)
    hit = keys[at] == want
    out[hit] = result.vg_fine[at[hit]]
    return out


def point_access(result: AccessResult, voxel: np.ndarray, face: np.ndarray) -> np.ndarray:
    """``A'`` (n, words) that the map gives surface points of ``face`` in boundary voxels
    ``voxel``: their face's piece's where several faces meet in the voxel (and the pieces were
    answered, ``result.amap_pieces``), else the voxel's."""
    return _by_piece(result.vm, result.amap, result.amap_pieces, np.asarray(voxel, dtype=np.int64),
                     np.asarray(face, dtype=np.int64))


def _by_piece(vm: VoxelMap, per_voxel: np.ndarray, per_piece: np.ndarray | None, voxel: np.ndarray,
              face: np.ndarray) -> np.ndarray:
    """Rows of ``per_voxel`` for ``voxel``, replaced by the (voxel, face) piece's row of
    ``per_piece`` where that piece exists."""
    from zmap.access.voxelmap import _piece_index

    out = per_voxel[voxel].copy()
    if vm.pieces is not None and per_piece is not None and len(per_piece) and vm.pieces.face is not None:
        pi = _piece_index(vm, voxel, face)
        out[pi >= 0] = per_piece[pi[pi >= 0]]
    return out


def agreement(part: Part, result: AccessResult, *, n_points: int = 60, seed: int = 0,
              tool: bool = False, samples: Samples | None = None, explain: bool = False,
              axis: str | None = None) -> dict:
    """Compare the voxel map with the OCC reference on random surface points x all k directions.

    ``tool=False`` compares ``V'_g`` with thin rays (:func:`reference_visibility`); ``tool=True``
    compares ``A'`` with :func:`reference_tool` (slow: one distance query per pair), the ball's
    centre outside the material of the map's rule (``result.vm.solid``). ``axis`` (e.g.
    ``'+z'``): that direction alone (with ``tool``, the 3-axis verdict of each point).
    The points' normals are turned as the map turned their faces (:meth:`VoxelMap.orient`).

    Returns
    -------
    dict
        ``pairs``, ``agree_share``; ``voxel_only`` (the map says free, the reference blocked:
        a non-conservative answer), split into ``voxel_only_near`` (the blocking hit within one
        voxel diagonal of the point; for the tool: OCC frees the pair with the shank and the
        holder one voxel diagonal thinner) and ``voxel_only_far``; ``reference_only`` (the map is
        conservative there); ``disagree`` and, with ``explain=True`` (thin rays only),
        ``disagree_near_silhouette``: disagreements where OCC answers otherwise for the same
        direction from a point one voxel diagonal away (along the tangent plane or the normal).
    """
    from zmap.access.directions import to_bool

    if int(n_points) < 1:
        raise ValueError(f"n_points must be at least 1 (the agreement of no points is no figure), got {n_points!r}")
    vm = result.vm
    ds = vm.directions
    s = samples if samples is not None else surface_samples(part, vm.step)
    rng = np.random.default_rng(seed)
    vox = vm.voxel_of(s.points)
    if not (vox >= 0).any():
        raise ValueError(f"none of the {len(s.points):,} surface samples of {part.source!r} lies in a voxel of the map")
    pick = rng.choice(np.flatnonzero(vox >= 0), size=min(n_points, int((vox >= 0).sum())), replace=False)
    pts, vb = s.points[pick], vox[pick]
    nrm = vm.orient(pts, s.normals[pick], s.face[pick])
    diag = np.sqrt(3.0) * vm.d
    cols = np.arange(ds.k) if axis is None else np.array([ds.index(axis)])
    dirs = ds.normals[cols]
    material = "below" if vm.solid == "below" else "closed"
    if tool:
        ref = reference_tool(part.shape, pts, nrm, dirs, result.tool, material=material)
        mine = to_bool(point_access(result, vb, s.face[pick]), ds.k)[:, cols]
        # a pair the map frees and OCC blocks: blocked within one voxel when OCC frees it with
        # the shank and the holder a voxel diagonal thinner (hit 0), else beyond (hit inf)
        hit = np.where(ref, np.inf, 0.0)
        for a, b in zip(*np.nonzero(mine & ~ref)):
            hit[a, b] = 0.0 if reference_tool(part.shape, pts[a:a + 1], nrm[a:a + 1], dirs[b:b + 1],
                                              result.tool, shrink=diag, material=material)[0, 0] else np.inf
    else:
        ref, hit = reference_visibility(part.shape, pts, dirs)
        mine = to_bool(point_visibility(result, vb, s.face[pick], pts), ds.k)[:, cols]
    vo = mine & ~ref
    near_sil = 0
    if not tool and explain:
        # a disagreement lies within one voxel of a silhouette (a shadow boundary) when the same
        # direction from a point one voxel diagonal away on the tangent plane gets the other answer
        for a, b in zip(*np.nonzero(mine != ref)):
            n = nrm[a]
            t1 = np.cross(n, [1.0, 0, 0] if abs(n[0]) < 0.9 else [0, 1.0, 0])
            t1 /= np.linalg.norm(t1)
            t2 = np.cross(n, t1)
            offs = pts[a] + diag * np.array([t1, -t1, t2, -t2, n * 0.5, -n * 0.5])
            free, _ = reference_visibility(part.shape, offs, dirs[b][None])
            if (free[:, 0] != ref[a, b]).any():
                near_sil += 1
    return {"pairs": int(ref.size), "agree_share": float((mine == ref).mean()),
            "disagree": int((mine != ref).sum()), "disagree_near_silhouette": near_sil,
            "voxel_only": int(vo.sum()), "voxel_only_near": int((vo & (hit <= diag)).sum()),
            "voxel_only_far": int((vo & (hit > diag)).sum()), "reference_only": int((ref & ~mine).sum()),
            "points": pts, "voxels": vb}


def top_faces(source, path=None, *, side_tol: float = 1e-3):
    """An open surface model of a die face, made from a solid: its faces less the block's
    bottom (downward planes at its lowest z) and outer walls (vertical faces on a side of its
    bounding box). A quilt of faces with free boundary edges and no solid, as die faces are
    often delivered.

    Parameters
    ----------
    source : str or path or OCP shape
        A STEP file or a shape.
    path : str or path, optional
        Where to write the model as STEP (written to a temporary name, then renamed).

    Returns
    -------
    shape : OCP TopoDS_Compound of the faces kept, and the number of faces kept and left out.

    Examples
    --------
    >>> shape, kept, left = top_faces("data/step/bug27693_cornetta-step.stp")  # doctest: +SKIP
    """
    import os
    import tempfile

    import cadquery as cq

    if isinstance(source, (str, os.PathLike)):
        solid = cq.importers.importStep(os.fspath(source)).val()
    else:
        solid = cq.Shape.cast(getattr(source, "wrapped", source))
    bb = solid.BoundingBox()
    keep = []
    faces = solid.Faces()
    for f in faces:
        n = f.normalAt()
        fb = f.BoundingBox()
        side = abs(n.z) < 1e-6 and (fb.xmin < bb.xmin + side_tol or fb.xmax > bb.xmax - side_tol
                                     or fb.ymin < bb.ymin + side_tol or fb.ymax > bb.ymax - side_tol)
        bottom = n.z < -1 + 1e-6 and fb.zmax < bb.zmin + side_tol
        if not (side or bottom):
            keep.append(f)
    comp = cq.Compound.makeCompound(keep)
    if path is not None:
        path = os.fspath(path)
        fd, tmp = tempfile.mkstemp(dir=os.path.dirname(os.path.abspath(path)), prefix=".tmp-", suffix=".step")
        os.close(fd)
        try:
            cq.exporters.export(comp, tmp, exportType="STEP")
            os.replace(tmp, path)
        finally:
            if os.path.exists(tmp):
                os.unlink(tmp)
    return comp.wrapped, len(keep), len(faces) - len(keep)
