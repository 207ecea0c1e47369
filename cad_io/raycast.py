"""An independent reference for the sampler: OCC ray casting, one ray per point.

Each query point shoots a ray along the view direction's opposite (along -z for ``+z``)
through the OCP shape with ``IntCurvesFace_ShapeIntersector`` and keeps the top-most hit.
Faces without a geometric surface (AP242 tessellated faces) are intersected with their
stored triangles (``BRep_Tool.Triangulation``, Moller-Trumbore). Slow (tens of
microseconds per ray and more): meant for a few thousand check points, not whole grids.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .view import view_matrix

__all__ = ["raycast", "RayCaster", "read_shape"]


class RayCaster:
    """Reusable ray caster over one shape seen from ``axis``.

    Parameters
    ----------
    shape : OCP TopoDS_Shape (or a cadquery Shape)
    axis : str
        View axis, one of ``cad_io.view.AXES``.
    tol : float
        Classification tolerance of the intersector, mm.
    """

    def __init__(self, shape: Any, *, axis: str = "+z", tol: float = 1e-7) -> None:
        from OCP.Bnd import Bnd_Box
        from OCP.BRep import BRep_Builder, BRep_Tool
        from OCP.BRepBndLib import BRepBndLib
        from OCP.IntCurvesFace import IntCurvesFace_ShapeIntersector
        from OCP.TopAbs import TopAbs_FACE
        from OCP.TopExp import TopExp
        from OCP.TopLoc import TopLoc_Location
        from OCP.TopoDS import TopoDS, TopoDS_Compound
        from OCP.TopTools import TopTools_IndexedMapOfShape

        shape = getattr(shape, "wrapped", shape)
        self.R = view_matrix(axis)
        fmap = TopTools_IndexedMapOfShape()
        TopExp.MapShapes_s(shape, TopAbs_FACE, fmap)
        self._faces = [TopoDS.Face_s(fmap.FindKey(i)) for i in range(1, fmap.Extent() + 1)]
        comp = TopoDS_Compound()
        builder = BRep_Builder()
        builder.MakeCompound(comp)
        tris = []  # triangles (world) of faces without a surface
        tri_face = []
        n_geom = 0
        self._geom: set[int] = set()
        for k, f in enumerate(self._faces):
            if BRep_Tool.Surface_s(f) is None:
                loc = TopLoc_Location()
                tri = BRep_Tool.Triangulation_s(f, loc)
                if tri is None:
                    continue
                trsf = loc.Transformation()
                nodes = np.array([[p.X(), p.Y(), p.Z()] for p in
                                  (tri.Node(i).Transformed(trsf) for i in range(1, tri.NbNodes() + 1))])
                idx = np.array([tri.Triangle(i).Get() for i in range(1, tri.NbTriangles() + 1)], dtype=np.int64) - 1
                tris.append(nodes[idx])
                tri_face.append(np.full(len(idx), k, dtype=np.int64))
            else:
                builder.Add(comp, f)
                n_geom += 1
                self._geom.add(k)
        self._tris = np.concatenate(tris) if tris else np.zeros((0, 3, 3))
        self._tri_face = np.concatenate(tri_face) if tri_face else np.zeros(0, dtype=np.int64)
        box = Bnd_Box()
        BRepBndLib.Add_s(shape, box, False)  # the geometry, not a mesh: the same rays however the shape is meshed
        xmin, ymin, zmin, xmax, ymax, zmax = box.Get()
        corners = np.array([[a, b, c] for a in (xmin, xmax) for b in (ymin, ymax) for c in (zmin, zmax)]) @ self.R.T
        self._top = float(corners[:, 2].max()) + 1.0
        self._depth = float(corners[:, 2].max() - corners[:, 2].min()) + 2.0
        self._inter = None
        if n_geom:
            self._inter = IntCurvesFace_ShapeIntersector()
            self._inter.Load(comp, tol)
        self._fmap = fmap
        self._tol = tol
        self._boxes = None  # faces' view-frame xy boxes, for :meth:`_face_by_face`
        self._single: dict = {}

    def _face_by_face(self, line: Any, x: float, y: float) -> tuple[float, int]:
        """Top-most hit of ``line`` (through view-frame ``(x, y)``) asking each face whose box
        it passes with its own ``IntCurvesFace_Intersector``.

        OCC's intersector throws Standard_NullObject on a face with a degenerated edge when
        a hit lies outside the face's trim curves but within the uv resolution of its edge
        tolerance (it projects the hit on every edge's 3D curve, and a degenerated edge has
        none). Such a face is asked again with its boundary tolerance off (its hits strictly
        inside only).
        """
        from OCP.Bnd import Bnd_Box
        from OCP.BRepBndLib import BRepBndLib
        from OCP.IntCurvesFace import IntCurvesFace_Intersector
        from OCP.TopAbs import TopAbs_OUT

        if self._boxes is None:
            boxes = np.full((len(self._faces), 4), np.nan)
            for k, f in enumerate(self._faces):
                box = Bnd_Box()
                BRepBndLib.Add_s(f, box, False)
                if box.IsVoid():
                    continue
                x0, y0, z0, x1, y1, z1 = box.Get()
                c = np.array([[a, b, d] for a in (x0, x1) for b in (y0, y1) for d in (z0, z1)]) @ self.R.T
                boxes[k] = c[:, 0].min(), c[:, 1].min(), c[:, 0].max(), c[:, 1].max()
            self._boxes = boxes
        b = self._boxes
        with np.errstate(invalid="ignore"):
            near = np.flatnonzero((b[:, 0] <= x) & (x <= b[:, 2]) & (b[:, 1] <= y) & (y <= b[:, 3]))
        best, zb, fb = np.inf, np.nan, -1
        for k in near.tolist():
            if k not in self._geom:
                continue  # triangles only: intersected by _ray_triangles
            for bound_tol in (True, False):
                key = (k, bound_tol)
                it = self._single.get(key)
                if it is None:
                    it = self._single[key] = IntCurvesFace_Intersector(self._faces[k], self._tol, True, bound_tol)
                try:
                    it.Perform(line, 0.0, self._depth)
                except Exception:  # noqa: BLE001
                    continue
                break
            else:
                continue
            if not it.IsDone():
                continue
            for i in range(1, it.NbPnt() + 1):
                if it.State(i) != TopAbs_OUT and it.WParameter(i) < best:
                    p = it.Pnt(i)
                    best = it.WParameter(i)
                    zb = float(self.R[2] @ np.array([p.X(), p.Y(), p.Z()]))
                    fb = k
        return zb, fb

    def _face_index(self, face: Any) -> int:
        i = self._fmap.FindIndex(face)
        return i - 1

    def __call__(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Top-most height and face index at view-frame points ``(x, y)``.

        Returns
        -------
        z : ndarray of float64, shape of ``x``
            View-frame height of the first hit; NaN where the ray misses.
        face : ndarray of int32
            Index of the hit face in ``TopExp.MapShapes`` order; -1 where none.
        """
        from OCP.gp import gp_Dir, gp_Lin, gp_Pnt
        from OCP.TopAbs import TopAbs_OUT

        x, y = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
        shape = x.shape
        xf, yf = x.ravel(), y.ravel()
        z = np.full(xf.size, np.nan)
        face = np.full(xf.size, -1, dtype=np.int32)
        R = self.R
        d = R.T @ np.array([0.0, 0.0, -1.0])
        direction = gp_Dir(*d.tolist())
        for n in range(xf.size):
            if self._inter is None:
                break
            o = R.T @ np.array([xf[n], yf[n], self._top])
            line = gp_Lin(gp_Pnt(*o.tolist()), direction)
            try:
                self._inter.Perform(line, 0.0, self._depth)
            except Exception:  # noqa: BLE001 (OCCT errors share no base class in OCP)
                # one face's intersector threw (Standard_NullObject on trj8's faces 22, 33,
                # 372), and the shape intersector lost the whole ray with it: ask the faces
                # the ray passes one by one
                z[n], face[n] = self._face_by_face(line, xf[n], yf[n])
                continue
            if not self._inter.IsDone():
                continue
            best = np.inf
            for i in range(1, self._inter.NbPnt() + 1):
                if self._inter.State(i) == TopAbs_OUT:
                    continue
                w = self._inter.WParameter(i)
                if w < best:
                    p = self._inter.Pnt(i)
                    best = w
                    z[n] = R[2] @ np.array([p.X(), p.Y(), p.Z()])
                    face[n] = self._face_index(self._inter.Face(i))
        if len(self._tris):
            tz, tf = _ray_triangles(self._tris @ R.T, self._tri_face, xf, yf)
            better = np.isfinite(tz) & ~(tz <= z)
            z[better] = tz[better]
            face[better] = tf[better]
        return z.reshape(shape), face.reshape(shape)


def _ray_triangles(tris: np.ndarray, tri_face: np.ndarray, x: np.ndarray, y: np.ndarray):
    """Top-most hit of vertical rays with triangles (view frame), plain numpy per point."""
    z = np.full(x.size, np.nan)
    face = np.full(x.size, -1, dtype=np.int32)
    a, b, c = tris[:, 0], tris[:, 1], tris[:, 2]
    lo = np.minimum(np.minimum(a, b), c)[:, :2]
    hi = np.maximum(np.maximum(a, b), c)[:, :2]
    e1, e2 = b - a, c - a
    dvec = np.array([0.0, 0.0, -1.0])
    for n in range(x.size):
        sel = np.nonzero((lo[:, 0] <= x[n]) & (hi[:, 0] >= x[n]) & (lo[:, 1] <= y[n]) & (hi[:, 1] >= y[n]))[0]
        if not len(sel):
            continue
        orig = np.array([x[n], y[n], 0.0])
        # Moller-Trumbore with the ray origin at z = 0 and direction -z: t = -z of the hit
        p = np.cross(dvec, e2[sel])
        det = np.einsum("ij,ij->i", e1[sel], p)
        ok = np.abs(det) > 1e-300
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        s = orig - a[sel]
        u = np.einsum("ij,ij->i", s, p) * inv
        q = np.cross(s, e1[sel])
        v = (q @ dvec) * inv
        t = np.einsum("ij,ij->i", e2[sel], q) * inv
        eps = 1e-12
        hit = ok & (u >= -eps) & (v >= -eps) & (u + v <= 1 + eps)
        if hit.any():
            k = np.argmin(np.where(hit, t, np.inf))
            z[n] = -t[k]
            face[n] = tri_face[sel[k]]
    return z, face


def read_shape(path) -> Any:
    """The OCP shape of a STEP file as OCC's own reader gives it (no conversion).

    Independent of :func:`cad_io.read_step`, so the reference does not share its code.
    """
    from OCP.IFSelect import IFSelect_RetDone
    from OCP.STEPControl import STEPControl_Reader

    from .step import _QuietFd

    with _QuietFd(1):  # OCC's reader messages go to stdout, which a bench's JSON owns
        reader = STEPControl_Reader()
        if reader.ReadFile(str(path)) != IFSelect_RetDone:
            raise OSError(f"{path}: OCC cannot read it as STEP")
        reader.TransferRoots()
        return reader.OneShape()


def raycast(shape: Any, x: np.ndarray, y: np.ndarray, *, axis: str = "+z", tol: float = 1e-7
            ) -> tuple[np.ndarray, np.ndarray]:
    """Top-most surface height at view-frame points by OCC ray casting.

    Parameters
    ----------
    shape : OCP TopoDS_Shape or cadquery Shape
    x, y : array_like, float64, mm
        Query points in the view frame (broadcast together).
    axis : str
        View axis ('+z', '-z', '+x', '-x', '+y', '-y'), see :mod:`cad_io.view`.
    tol : float
        Intersector tolerance, mm.

    Returns
    -------
    z : ndarray of float64
        Height along the view axis; NaN where the ray meets no face.
    face : ndarray of int32
        Index (``TopExp.MapShapes`` order, i.e. explorer order) of the face hit; -1 if none.

    Examples
    --------
    >>> import cadquery as cq
    >>> box = cq.Workplane().box(10, 10, 4).val()
    >>> z, f = raycast(box, [0.0, 20.0], [0.0, 0.0])
    >>> float(z[0]), bool(np.isnan(z[1]))
    (2.0, True)
    """
    return RayCaster(shape, axis=axis, tol=tol)(x, y)
