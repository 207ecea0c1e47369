"""The fine facet pass of the z-map sampler: the points a coarse start mesh answered by facets
on exact faces (Newton failed there) are solved again on a fine mesh of the faces that may
cover them, each face meshed alone at the fine deflection and kept on the part, or ray-cast
by OCC where its fine mesh would be too large.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ._sample_pairs import JACOBIAN
from ._sample_points import sample_points
from .part import Part

if TYPE_CHECKING:
    from .part import FaceMesh
    from .raycast import RayCaster

__all__ = ["FINE_FACE_TRIANGLES", "_face_caster", "_fine_facets", "fine_cast"]

#: the fine facet pass meshes a face (alone, on a copy) when its fine mesh is estimated at no
#: more than this many triangles (about 300 MB of BRepMesh's working memory); the points of a
#: larger face get OCC's exact ray cast on that face instead. BRepMesh needs about 2.3 KB a
#: triangle while it works (bm2's face 10 at 1.5 um: 180,372 triangles, 580 MB) and
#: its count on large B-spline faces is not predictable: bm2's 1 m face 3 at 5 um gave
#: 195,100 triangles (13.5 s, 455 MB), the whole part at 1.5 um 8.4 GB, and a 245 mm piece
#: of its face 2 cut out with a Boolean, 1.43 M triangles (313 s, 15 GB)
FINE_FACE_TRIANGLES = 100_000
#: triangles of whole-face fine meshes kept on a part between calls of the fine pass
_FINE_CACHE_TRIANGLES = 2 * FINE_FACE_TRIANGLES
_FINE_CACHE_ATTR = "_fine_mesh_cache"
_CASTER_ATTR = "_fine_ray_casters"


def _covering_faces(vpart: Part, gx: np.ndarray, gy: np.ndarray, pad: float) -> np.ndarray:
    """Indices of the faces whose view-frame bounding box, widened by ``pad`` mm, holds one
    of the points (``gx``, ``gy``); faces without a box are always listed."""
    order = np.argsort(gx, kind="stable")
    xs, ys = gx[order], gy[order]
    out = []
    for k, f in enumerate(vpart.faces):
        b = np.asarray(f.bbox, dtype=np.float64)
        if not np.all(np.isfinite(b)):
            out.append(k)
            continue
        lo = np.searchsorted(xs, b[0] - pad, side="left")
        hi = np.searchsorted(xs, b[3] + pad, side="right")
        if hi > lo and np.any((ys[lo:hi] >= b[1] - pad) & (ys[lo:hi] <= b[4] + pad)):
            out.append(k)
    return np.asarray(out, dtype=np.int64)


def _fine_enough(mesh: FaceMesh | None, fine: float) -> bool:
    """Whether a face's own mesh is at deflection ``fine`` or finer (the fine facet pass then
    uses it as it is: neither meshed again nor ray-cast)."""
    return mesh is not None and float(mesh.deflection) <= fine


def fine_cast(part: Part, fine: float) -> np.ndarray:
    """Per face of ``part``: True where the fine facet pass ray-casts the face instead of
    meshing it at ``fine``.

    A face's fine triangle count is estimated from its current mesh, scaled by the ratio of
    deflections (BRepMesh's count grows about as 1/deflection on curved faces: bm2's face 2
    has 4,512 triangles at 0.5 mm and 77,079 at 0.03). The answer depends only on the face
    and its mesh, so a tile of a tiled conversion treats each face as the whole map does.

    Parameters
    ----------
    part : cad_io.Part
        Meshed (faces without a mesh, a surface or an OCC shape are never cast).
    fine : float
        Deflection of the fine facet pass, mm.

    Returns
    -------
    ndarray of bool, shape (len(part.faces),)
        True for the faces whose fine mesh would hold more than
        :data:`FINE_FACE_TRIANGLES` triangles.
    """
    out = np.zeros(len(part.faces), dtype=np.bool_)
    if part.shape is None:
        return out  # geomdl faces are meshed on cheap (u, v) grids
    for k, face in enumerate(part.faces):
        mesh = face.mesh
        if mesh is None or not len(mesh.triangles) or face.surface is None:
            continue  # (a face without a surface keeps its stored triangles)
        if _fine_enough(mesh, fine):
            continue  # the pass uses its own mesh as it is
        out[k] = len(mesh.triangles) * max(float(mesh.deflection) / fine, 1.0) > FINE_FACE_TRIANGLES
    return out


def _whole_fine_meshes(part: Part, faces: np.ndarray, fine: float) -> list[FaceMesh | None]:
    """Fine meshes of ``part``'s faces ``faces``, each meshed alone on a copy (so the same
    whatever other faces a call needs) and kept on the part for the next calls; a face whose
    own mesh is already at ``fine`` or finer (a part triangulated that finely by its user)
    keeps it (meshing it again, or ray-casting a face whose fine mesh is large, took the
    die's 1000 x 1000 facet map from 0.46 to 111 CPU-s)."""
    from .mesh import mesh_faces_alone

    cache = part.__dict__.setdefault(_FINE_CACHE_ATTR, {})
    if cache.get("fine") != fine:
        cache.clear()
        cache.update(fine=fine, meshes={})
    meshes = cache["meshes"]
    own = {int(k): part.faces[int(k)].mesh for k in faces if _fine_enough(part.faces[int(k)].mesh, fine)}
    missing = [int(k) for k in faces if int(k) not in meshes and int(k) not in own]
    for k, mesh in zip(missing, mesh_faces_alone(part, missing, fine) if missing else []):
        meshes[k] = mesh
    out = [own[int(k)] if int(k) in own else meshes[int(k)] for k in faces]
    held = sum(len(m.triangles) for m in meshes.values() if m is not None)
    used = set(faces.tolist())
    for k in list(meshes):  # the oldest first, but never one this call uses
        if held <= _FINE_CACHE_TRIANGLES:
            break
        if k not in used and meshes[k] is not None:
            held -= len(meshes[k].triangles)
            del meshes[k]
    return out


def _face_caster(part: Part, k: int, axis: str) -> RayCaster:
    """OCC ray caster (:class:`cad_io.raycast.RayCaster`) of face ``k`` alone, kept on the part."""
    from .raycast import RayCaster

    casters = part.__dict__.setdefault(_CASTER_ATTR, {})
    hit = casters.get((k, axis))
    if hit is None:
        from OCP.TopAbs import TopAbs_FACE
        from OCP.TopExp import TopExp
        from OCP.TopTools import TopTools_IndexedMapOfShape

        fmap = TopTools_IndexedMapOfShape()
        TopExp.MapShapes_s(part.shape, TopAbs_FACE, fmap)
        hit = casters[(k, axis)] = RayCaster(fmap.FindKey(k + 1), axis=axis)
    return hit


def _fine_facets(part: Part, vpart: Part, gx: np.ndarray, gy: np.ndarray, fine: float, coarse: float,
                 method: str, axis: str, cast: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """:func:`sample_points` at deflection ``fine`` on the faces that may cover the points.

    Only the faces whose bounding box (seen from ``axis``) holds a point can give it a height
    (a face's box is widened by its edge tolerance and two coarse deflections). Each is
    meshed at ``fine`` alone on a copy (kept on the part for later calls), except the faces
    ``cast`` (:func:`fine_cast`) whose fine mesh would be too large: their points get OCC's
    exact ray cast on the face (method 1, exact, as a Jacobian answer). The answer at a point
    does not depend on the other points of a call, and the part's own meshes and OCC
    triangulations stay as they are. Returns the heights, face indices into ``part.faces``,
    methods, and the number of faces meshed or cast.
    """
    import dataclasses

    n = gx.size
    z = np.full(n, np.nan)
    f = np.full(n, -1, dtype=np.int32)
    m = np.zeros(n, dtype=np.int8)
    pad = 2.0 * coarse + max([float(getattr(fc, "tolerance", 0.0)) for fc in part.faces] + [0.0])
    keep = _covering_faces(vpart, gx, gy, pad)
    if keep.size == 0:
        return z, f, m, 0
    cast = np.asarray(cast, dtype=np.bool_) & (part.shape is not None)
    whole, big = keep[~cast[keep]], keep[cast[keep]]
    if whole.size:
        meshes = _whole_fine_meshes(part, whole, fine) if part.shape is not None else [None] * whole.size
        faces = [dataclasses.replace(part.faces[int(k)], index=i, mesh=mesh) for i, (k, mesh) in enumerate(zip(whole, meshes))]
        sub = Part(faces=faces, source=part.source, shape=None)
        z, fs_, m = sample_points(sub, gx, gy, deflection=fine, method=method, axis=axis)
        f = np.where(fs_ >= 0, whole[np.maximum(fs_, 0)], -1).astype(np.int32)
    for k in big.tolist():
        b = np.asarray(vpart.faces[k].bbox, dtype=np.float64)
        sel = np.flatnonzero((gx >= b[0] - pad) & (gx <= b[3] + pad) & (gy >= b[1] - pad) & (gy <= b[4] + pad))
        if not sel.size:
            continue
        zr, _ = _face_caster(part, k, axis)(gx[sel], gy[sel])
        top = np.isfinite(zr) & ~(zr <= z[sel])  # NaN in z: the ray's hit is the top
        z[sel[top]], f[sel[top]], m[sel[top]] = zr[top], k, JACOBIAN
    return z, f, m, int(keep.size)
