"""The face set of the z-map sampler: every face's mesh, seen from the view axis, packed with
what the pair kernels need per face and triangle (its NURBS, which triangles test their
answers against the trim loops and how far outside they pair, the layer gap a Newton answer
may stand from its facet), and its cache on the part.

A face without a (u, v) triangulation starts from a uv lattice, one whose mesh misses its
deflection (BRepMesh on edges with a large tolerance) from a (u, v) grid of exact surface
points; a face without a usable NURBS goes to facets.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

from zmap.errors import NurbsError

from ._sample_trim import TRIM_SLACK_MM, _loop_bulges, _tolerance_band, _trim_bands, _trim_slack_uv, _with_band
from .view import transform_part

if TYPE_CHECKING:
    from .nurbs import PackedNurbs
    from .part import FaceMesh, NurbsSurface, Part

__all__ = ["BOUNDARY_MARGIN", "ERROR_SAMPLES", "LATTICE", "MESH_ERROR_SHARE", "SILHOUETTE_RINGS", "STEEP_NZ",
           "TIGHT_MESH_ERROR_SHARE", "_FaceSet", "_cached_face_set", "_face_set", "_needs_mesh",
           "_silhouette_triangles", "_steep_triangles"]

#: uv lattice size for faces with a surface but no (u, v) triangulation
LATTICE = 48
#: Boundary triangles of an exact face pair with points up to this many mesh deflections
#: outside them (Newton and the trim test then decide)
BOUNDARY_MARGIN = 2.0


def _boundary_triangles(tris: np.ndarray) -> np.ndarray:
    """True for triangles with a node on the mesh boundary (an edge used once)."""
    if len(tris) == 0:
        return np.zeros(0, dtype=np.bool_)
    e = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    e.sort(axis=1)
    key = e[:, 0].astype(np.int64) * (int(tris.max()) + 1) + e[:, 1]
    uniq, inv, cnt = np.unique(key, return_inverse=True, return_counts=True)
    bnodes = np.zeros(int(tris.max()) + 1, dtype=np.bool_)
    once = cnt[inv] == 1
    bnodes[e[once, 0]] = True
    bnodes[e[once, 1]] = True
    return bnodes[tris].any(axis=1)


#: |n_z| below which a mesh triangle may border a silhouette of its face in the view
STEEP_NZ = 0.25
#: rings of triangles around a fold edge that get the silhouette margin (see _silhouette_triangles)
SILHOUETTE_RINGS = 2


def _steep_triangles(nodes: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """True for triangles steeper than ~75 degrees in the view (|n_z| < :data:`STEEP_NZ`)."""
    if len(tris) == 0:
        return np.zeros(0, dtype=np.bool_)
    a, b, c = nodes[tris[:, 0]], nodes[tris[:, 1]], nodes[tris[:, 2]]
    n = np.cross(b - a, c - a)
    nn = np.linalg.norm(n, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return ~(np.abs(n[:, 2]) >= STEEP_NZ * nn)


def _silhouette_triangles(nodes: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """True for steep triangles (:func:`_steep_triangles`) near a fold of the mesh in the view.

    A fold is an interior mesh edge whose two triangles face opposite ways along the view
    axis (their n_z differ in sign) or one of which is edge-on (n_z within 1e-9 of 0, no
    xy area). The true silhouette of the face lies within about a deflection of such an
    edge, possibly outside the mesh's outline, where no triangle covers a grid row on it;
    the steep triangles within :data:`SILHOUETTE_RINGS` node rings of a fold pair with
    points up to the boundary margin outside them. A face's own outline (an edge used
    once) is handled by the boundary triangles. Steep triangles elsewhere (walls seen
    from above: cornetta's 84-86 degree faces) get no margin: there it only added pairs
    that Newton then ran off the face for, doubling cornetta's time at grid/20.
    """
    M = len(tris)
    if M == 0:
        return np.zeros(0, dtype=np.bool_)
    steep = _steep_triangles(nodes, tris)
    if not steep.any():
        return steep
    a, b, c = nodes[tris[:, 0]], nodes[tris[:, 1]], nodes[tris[:, 2]]
    n = np.cross(b - a, c - a)
    nn = np.linalg.norm(n, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        nz = np.where(nn > 0, n[:, 2] / nn, 0.0)
    sign = np.where(np.abs(nz) <= 1e-9, 0, np.sign(nz)).astype(np.int8)
    e = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]).astype(np.int64)
    e.sort(axis=1)
    et = np.tile(np.arange(M), 3)
    key = e[:, 0] * (int(tris.max()) + 1) + e[:, 1]
    order = np.argsort(key, kind="stable")
    ks = key[order]
    same = np.flatnonzero(ks[1:] == ks[:-1])  # consecutive pairs: an interior edge's two triangles
    t1, t2 = et[order[same]], et[order[same + 1]]
    fold = (sign[t1] != sign[t2]) | (sign[t1] == 0) | (sign[t2] == 0)
    hot = np.zeros(int(tris.max()) + 1, dtype=np.bool_)
    fe = e[order[same[fold]]]
    hot[fe[:, 0]] = True
    hot[fe[:, 1]] = True
    near = hot[tris].any(axis=1)
    for _ in range(SILHOUETTE_RINGS - 1):
        hot[tris[near].ravel()] = True
        near = hot[tris].any(axis=1)
    return steep & near


#: triangles per face whose centroids :func:`_mesh_errors` checks against the surface
ERROR_SAMPLES = 4096
#: a face's mesh counts as missing its deflection where the measured error exceeds it this
#: many times (trj8: 80-160x at 5 um)
MESH_ERROR_SHARE = 3.0
#: the same for a face whose edges are within the deflection. Below 5x the layer check (20
#: deflections vertically, 10 across a steep triangle) refuses no Newton answer on a face
#: that is not a wall, and the centroid measure reads a sound mesh at up to about 3.3x
#: (the die's: regridded, its Jacobian map took 1.65 CPU-s instead of 0.71). trj8's steep
#: face 361 (edges 1e-3 mm) is 12x off, and its facets answered 0.18 mm low
TIGHT_MESH_ERROR_SHARE = 5.0


def _mesh_errors(packed: PackedNurbs, meshes: dict[int, Any]) -> dict[int, float]:
    """Per face, the largest distance (mm) between a mesh triangle's centroid and the surface
    point at the centroid's (u, v), over up to :data:`ERROR_SAMPLES` triangles.

    BRepMesh does not hold the deflection asked for on a face whose edges carry a large
    tolerance (it meshes such a face at about twice its tolerance): trj8's faces, edges up
    to 0.95 mm, are 0.4-0.8 mm off their surface at a requested 5 um. The Newton starts'
    layer check and boundary margin must use the error the mesh has, not the one asked for:
    with the asked one, Newton's exact answers were refused as "another layer" and facets
    0.8 mm off answered instead (53.8 M of trj8's 95 M e-points at grid 0.5). Triangles
    whose centroid lies more than half their longest side from the surface point (across a
    periodic seam) are not counted.
    """
    from .nurbs import evaluate_packed

    ks, us, vs, cs, ls = [], [], [], [], []
    for k, m in meshes.items():
        t = np.asarray(m.triangles)
        if len(t) > ERROR_SAMPLES:
            t = t[np.linspace(0, len(t) - 1, ERROR_SAMPLES).astype(np.int64)]
        uvc = np.asarray(m.uv)[t].mean(axis=1)
        p = np.asarray(m.nodes)[t]
        ks.append(np.full(len(t), k))
        us.append(uvc[:, 0])
        vs.append(uvc[:, 1])
        cs.append(p.mean(axis=1))
        ls.append(np.linalg.norm(p - np.roll(p, 1, axis=1), axis=2).max(axis=1))
    if not ks:
        return {}
    k_all = np.concatenate(ks)
    s = evaluate_packed(packed, k_all, np.concatenate(us), np.concatenate(vs))[:, 0]
    d = np.linalg.norm(s - np.concatenate(cs), axis=1)
    # a triangle across a periodic seam has nodes at both ends of the uv domain, and its
    # uv centroid maps across the face (nist_ctc_02's face 55: 212 mm): a chord's sag is
    # less than half its length, so such a triangle says nothing of the mesh's error
    d[~(d <= 0.5 * np.concatenate(ls))] = 0.0
    out = {}
    ends = np.cumsum([len(a) for a in ks])
    for k, e, n in zip(meshes, ends, (len(a) for a in ks)):
        dk = d[e - n:e]
        out[k] = float(np.nanmax(dk)) if n and np.isfinite(dk).any() else 0.0
    return out


def _lattice_mesh(surface: NurbsSurface, n: int) -> FaceMesh:
    """Triangles of an ``n`` x ``n`` lattice over the untrimmed (u, v) domain of ``surface``.

    The start of the issue's plain method (nearest point of a coarse uv lattice), for faces
    that came without a triangulation in (u, v).
    """
    from .part import FaceMesh
    from .nurbs import evaluate

    u0, u1, v0, v1 = surface.domain
    U, V = np.meshgrid(np.linspace(u0, u1, n), np.linspace(v0, v1, n), indexing="ij")
    nodes = evaluate(surface, U, V)[..., 0, :].reshape(-1, 3)
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    tris = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.int32)
    return FaceMesh(np.ascontiguousarray(nodes), tris, np.stack([U.ravel(), V.ravel()], 1), 0.0)


def _needs_mesh(part: Part, deflection: float) -> bool:
    """Whether a face of ``part`` has no mesh, or an exact face one coarser than ``deflection``."""
    for f in part.faces:
        m = f.mesh
        if m is None:
            return True
        if f.surface is not None and m.uv is not None and m.deflection > deflection * (1 + 1e-9):
            return True
    return False


@dataclass
class _FaceSet:
    """Every face's mesh concatenated, with what the pair kernels need per face and triangle."""

    packed: Any
    nodes: np.ndarray | None = None
    uv: np.ndarray | None = None
    tris: np.ndarray | None = None
    tri_face: np.ndarray | None = None
    tri_check: np.ndarray | None = None
    tri_margin: np.ndarray | None = None
    face_mode: np.ndarray | None = None
    face_zgap: np.ndarray | None = None
    trim: tuple = ()
    msgs: list = field(default_factory=list)

    def solve_args(self) -> tuple:
        """Arguments of ``solve_pairs``/``solve_pairs_xy`` from ``nodes`` to ``face_bf``."""
        pk = self.packed
        return (self.nodes, self.uv, self.tris, self.tri_face, self.tri_check, self.face_mode, self.face_zgap,
                pk.deg, pk.ncp, pk.koff, pk.poff, pk.knots, pk.cpw,
                np.ascontiguousarray(np.nan_to_num(pk.domain)), *self.trim)


def _in_window(b: Sequence[float], window: Sequence[float] | None) -> bool:
    """False where the box ``b`` (x0, y0, z0, x1, y1, z1) misses ``window = (x0, y0, x1, y1)``."""
    return window is None or not np.all(np.isfinite(b)) or not (
        b[3] < window[0] or b[0] > window[2] or b[4] < window[1] or b[1] > window[3])


def _face_set(vpart: Part, deflection: float, window: Sequence[float] | None = None) -> _FaceSet:
    """Pack the faces of ``vpart`` (view frame, meshed) for the pair kernels.

    Faces whose bounding box misses ``window = (x0, y0, x1, y1)`` are left out; faces
    without a (u, v) triangulation get a uv lattice; faces without a usable NURBS go to
    facets. ``msgs`` says which faces took which path.
    """
    from .mesh import trimmed_grid_mesh
    from .nurbs import pack

    msgs: list[str] = []
    surfaces = [f.surface for f in vpart.faces]
    try:
        packed = pack(surfaces)
    except NurbsError:
        bad = []
        for k, s in enumerate(surfaces):
            if s is not None:
                try:
                    pack([s])
                except NurbsError:
                    surfaces[k] = None
                    bad.append(k)
        msgs.append(f"faces {bad} have NURBS the evaluator rejects: sampled from facets")
        packed = pack(surfaces)
    no_surface = [f.index for f, s in zip(vpart.faces, surfaces) if s is None]
    if no_surface:
        msgs.append(f"{len(no_surface)} faces without NURBS surface sampled from facets: ids {_ids(no_surface)}")
    no_mesh = [f.index for f, s in zip(vpart.faces, surfaces)
               if (f.mesh is None or len(f.mesh.triangles) == 0) and s is None]
    if no_mesh:
        msgs.append(f"{len(no_mesh)} faces without surface or triangles skipped: ids {_ids(no_mesh)}")
    lattice = [f.index for f, s in zip(vpart.faces, surfaces)
               if (f.mesh is None or len(f.mesh.triangles) == 0 or f.mesh.uv is None) and s is not None]
    if lattice:
        msgs.append(f"{len(lattice)} faces without a (u, v) triangulation started from a "
                    f"{LATTICE} x {LATTICE} uv lattice: ids {_ids(lattice)}")

    F = len(vpart.faces)
    fs = _FaceSet(packed=packed, msgs=msgs)
    fs.face_mode = np.full(F, 2, dtype=np.int8)
    fs.face_zgap = np.full(F, 1e-6)
    face_loops: dict[int, list[np.ndarray]] = {}
    face_mm: dict[int, np.ndarray] = {}
    face_bulge: dict[int, np.ndarray] = {}
    nodes_l, uv_l, tris_l, tface_l, check_l, margin_l = [], [], [], [], [], []
    n_nodes = 0
    lattice_set = set(lattice)
    # every face: BRepMesh misses the deflection where the edges carry a larger tolerance
    # (trj8), but also on some faces with tight edges (trj8's steep face 361, edges 1e-3 mm:
    # 66 triangles 0.06 mm off at 5 um asked; its facets answered 0.18 mm low). A sound
    # mesh stays within MESH_ERROR_SHARE (TIGHT_MESH_ERROR_SHARE) and keeps its margins
    errors = _mesh_errors(packed, {k: f.mesh for k, f in enumerate(vpart.faces)
                                   if surfaces[k] is not None and k not in lattice_set and f.mesh is not None
                                   and f.mesh.uv is not None and len(f.mesh.triangles)
                                   and _in_window(f.bbox, window)})
    for k, f in enumerate(vpart.faces):
        m = f.mesh
        on_lattice = k in lattice_set
        if on_lattice:
            m = _lattice_mesh(surfaces[k], LATTICE)
        if m is None or len(m.triangles) == 0:
            continue
        if not _in_window(f.bbox, window):
            continue
        # the mesh's own deflection, or the error it has where BRepMesh did not reach it
        # (the centroid measure also counts a tangential shift of the uv centroid, up to
        # about twice the sag on a sound mesh: only a mesh off by more is taken at its error;
        # otherwise the margins grew by 9% of the die's pairs for nothing)
        md = m.deflection
        regrid = False
        tight = float(getattr(f, "tolerance", 0.0) or 0.0) <= m.deflection
        if errors.get(k, 0.0) > (TIGHT_MESH_ERROR_SHARE if tight else MESH_ERROR_SHARE) * m.deflection:
            md = errors[k]
            if m.uv is not None and f.loops is not None:
                # BRepMesh missed the deflection (it meshes at about twice the edges'
                # tolerance: trj8's faces 0.4-0.6 mm off at 10 um asked): a (u, v) grid of
                # exact surface points instead, over the trimmed region and the edges'
                # tolerance band beyond it. With BRepMesh's triangles and margins of twice
                # their error, trj8's e-points paired 28 triangles each on its worst faces
                # and Newton ran 55 us a pair
                m = trimmed_grid_mesh(f, m.deflection, float(getattr(f, "tolerance", 0.0) or 0.0)
                                      + BOUNDARY_MARGIN * m.deflection)
                md = max(m.deflection, deflection * 1e-3)
                regrid = True
        if surfaces[k] is not None and m.uv is not None:
            fs.face_mode[k] = 1
            fs.face_zgap[k] = np.inf if on_lattice else max(20.0 * max(md, deflection), 1e-6)
            lps = [np.asarray(lp, dtype=np.float64).reshape(-1, 2) for lp in f.loops]
            face_loops[k] = [lp for lp in lps if len(lp) >= 3]
            bulge = _loop_bulges(f, lps)
            if bulge is not None and float(getattr(f, "tolerance", 0.0) or 0.0) > 0:
                # the loops follow the trim curves (their bulges): the slack is the file's
                face_bulge[k] = bulge
                face_mm[k] = np.full(len(bulge), min(TRIM_SLACK_MM, float(f.tolerance)))
        tri = np.asarray(m.triangles, dtype=np.int64)
        nodes_l.append(np.asarray(m.nodes, dtype=np.float64))
        uv_l.append(np.asarray(m.uv, dtype=np.float64) if m.uv is not None else np.zeros((len(m.nodes), 2)))
        tris_l.append(tri + n_nodes)
        tface_l.append(np.full(len(tri), k, dtype=np.int64))
        # a lattice covers the untrimmed domain: every solution is tested against the loops
        outline = _boundary_triangles(tri)
        # a lattice or grid covers more than the trimmed face: every solution is tested
        check = np.ones(len(tri), dtype=np.bool_) if on_lattice or regrid else outline.copy()
        if fs.face_mode[k] == 1 and not on_lattice:
            # a silhouette of the face seen from the view axis (a fold: the top of a torus
            # seen from the side, a fillet's tangent line) lies up to the deflection outside
            # the mesh's outline, where no triangle covers a grid row on it: steep triangles
            # by a fold pair with points that far outside too, and their solutions are
            # trim-tested
            sil = _silhouette_triangles(np.asarray(m.nodes, dtype=np.float64), tri)
            check |= sil
            outline |= sil
        check_l.append(check)
        # a mesh's boundary polygon may cut up to its deflection inside a curved trim
        # boundary: boundary triangles of an exact face pair with points that far outside.
        # The mesh's own deflection, not the one asked for: a part meshed finer than the
        # call needs (bench/convert.py's jacobian_pps: grid / 20 for a grid-sized request)
        # took 20x the margin, and cornetta 2.2 M pairs instead of 1.2 M (6.7 s, not 1.8 s),
        # with the same map
        md = md if md > 0 else deflection
        margin = BOUNDARY_MARGIN * md if fs.face_mode[k] == 1 else 0.0
        if margin and not regrid and f.topo is not None and float(getattr(f, "tolerance", 0.0)) > TRIM_SLACK_MM:
            # and as far as the edges' tolerance beyond the boundary, within which OCC's ray
            # cast still sees the face (:func:`_tolerance_band`; BRepMesh's error on such a
            # face, about twice the tolerance, mostly covers it already)
            margin = max(margin, md + float(f.tolerance))
        # a grid reaches past the tolerance band itself: its own outline takes the margin
        margin_l.append(np.where(outline if regrid else check, margin, 0.0))
        n_nodes += len(m.nodes)
    if tris_l:
        fs.nodes = np.ascontiguousarray(np.concatenate(nodes_l))
        fs.uv = np.ascontiguousarray(np.concatenate(uv_l))
        fs.tris = np.ascontiguousarray(np.concatenate(tris_l))
        fs.tri_face = np.ascontiguousarray(np.concatenate(tface_l))
        fs.tri_check = np.ascontiguousarray(np.concatenate(check_l))
        fs.tri_margin = np.ascontiguousarray(np.concatenate(margin_l))
        slack = _trim_slack_uv(packed, face_loops, F, face_mm)
        band = _tolerance_band(vpart, face_loops)
        reach = {k: float(band[0][k, 1]) for k in np.flatnonzero(band[0][:, 0] > 0).tolist()}
        fs.trim = _with_band(_trim_bands(face_loops, np.nan_to_num(packed.domain), F, slack, reach, face_bulge),
                             band)
    return fs


def _ids(ids: list[int], limit: int = 20) -> str:
    """The first ``limit`` of ``ids`` for a message, and how many more."""
    s = ", ".join(str(i) for i in ids[:limit])
    return s + (f", ... ({len(ids) - limit} more)" if len(ids) > limit else "")


#: attribute of a part that holds its face sets (:func:`_cached_face_set`)
_CACHE_ATTR = "_sampler_cache"


def _cached_face_set(part: Part, deflection: float, axis: str) -> _FaceSet:
    """The part's :class:`_FaceSet` at ``deflection``, meshed once and kept on the part.

    The cache is keyed by deflection and axis and checked against the faces' current
    meshes, so a later :func:`cad_io.triangulate` of the part rebuilds it. Only face sets
    of the current meshes are kept: a face set holds every node and triangle of the part
    (about 0.1 KB a triangle), and the entries of meshes replaced by a finer triangulation
    would otherwise stay alive with the part.
    """
    cache = part.__dict__.setdefault(_CACHE_ATTR, {})
    key = (float(deflection), axis)
    hit = cache.get(key)
    if hit is not None and hit[0] == tuple(id(f.mesh) for f in part.faces):
        return hit[1]
    if _needs_mesh(part, deflection):
        from .mesh import triangulate

        triangulate(part, deflection)
    ids = tuple(id(f.mesh) for f in part.faces)
    for k in [k for k, (mesh_ids, _) in cache.items() if mesh_ids != ids]:
        del cache[k]
    fs = _face_set(transform_part(part, axis), deflection)
    cache[key] = (ids, fs)
    return fs
