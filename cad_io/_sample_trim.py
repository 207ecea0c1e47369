"""Trim loops of the z-map sampler's faces as its kernels read them: each face's loop edges
bucketed in bands of v, with the slack a point on a curved boundary needs (a loop is a
polyline), the bulge of the true trim curve beside each edge, and the band of the file's
edge tolerance within which OCC's ray cast still sees a face.

The tests themselves are the kernels of :mod:`cad_io._trim_kernels`; the face set
(:mod:`cad_io._sample_faces`) builds these arrays for them.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from .nurbs import PackedNurbs
    from .part import Face, Part

__all__ = ["TRIM_SLACK_MM", "_loop_bulges", "_tolerance_band", "_trim_bands", "_trim_slack_uv", "_with_band"]

#: Points this close (mm) to a face's trim loop count as inside it: the loops are polylines
#: within about 1e-4 mm of the true boundary (see _trim_slack_uv). A face whose edges carry a
#: larger tolerance in the file also holds the points OCC's ray cast counts as on it within
#: that tolerance (``_trim_kernels.in_tolerance``).
TRIM_SLACK_MM = 5e-4


def _loop_bulges(face: Face, lps: list[np.ndarray]) -> np.ndarray | None:
    """Per loop edge of ``face`` (its loops of 3 points or more) the bulge of the true trim
    curve beside it (``Face.loop_bulges``); None where not known (geomdl input)."""
    bulges = list(getattr(face, "loop_bulges", None) or [])
    if len(bulges) != len(lps) or any(len(b) != len(lp) for b, lp in zip(bulges, lps)):
        return None
    keep = [np.asarray(b, dtype=np.float64) for b, lp in zip(bulges, lps) if len(lp) >= 3]
    return np.concatenate(keep) if keep else None


def _trim_slack_uv(packed: PackedNurbs, face_loops: dict[int, list[np.ndarray]], F: int,
                   face_mm: dict[int, np.ndarray] | None = None) -> dict[int, np.ndarray]:
    """Per face, per loop edge, the uv distance across the edge that spans
    ``face_mm[k]`` (:func:`_loop_slack_mm`; :data:`TRIM_SLACK_MM` where not given) on the
    surface.

    The trim loops are polylines within about 1e-4 mm of the true boundary, so a point
    exactly on a curved boundary can fall just outside the polygon of both faces that meet
    there (a wall's top edge and the fillet below it), and a lower face would answer. A
    point within the slack of a loop counts as inside. (A file's larger edge tolerances are
    honoured as OCC's ray cast honours them, by :func:`_tolerance_band`: widening the slack
    to the tolerance made trj8's faces, edges of 0.2-0.3 mm, claim points 0.2 mm beyond
    their loops that OCC gives to the face beside, 0.04 mm lower.)

    The scale is measured across each loop edge, ``|S_u n_u + S_v n_v|`` at its midpoint
    for the uv normal ``n`` of the edge: one scale per face (the median of |dS| / |duv|
    along the loop, as before) let cornetta's face 3, 1 mm per u but 70 mm per v, claim a
    point 0.33 mm outside it, 18 mm above the floor OCC sees there.
    """
    from .nurbs import evaluate_packed

    out: dict[int, np.ndarray] = {}
    for k, lps in face_loops.items():
        if not lps:
            continue
        a = np.concatenate(lps)
        b = np.concatenate([np.roll(lp, -1, axis=0) for lp in lps])
        d = b - a
        duv = np.hypot(d[:, 0], d[:, 1])
        m = 0.5 * (a + b)
        der = evaluate_packed(packed, np.full(len(m), k), m[:, 0], m[:, 1], derivs=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            nu, nv = -d[:, 1] / duv, d[:, 0] / duv
            across = np.linalg.norm(der[:, 1, :] * nu[:, None] + der[:, 2, :] * nv[:, None], axis=1)
        mm = face_mm.get(k, TRIM_SLACK_MM) if face_mm else TRIM_SLACK_MM
        ok = np.isfinite(across) & (across > 0) & (duv > 0)
        slack = np.zeros(len(a))
        if ok.any():
            # a degenerate edge (a pole) borrows the median scale of the loop
            fallback = float(np.median(across[ok]))
            scale = np.where(ok, across, fallback)
            span = float(np.nanmax(np.r_[np.ptp(a[:, 0]), np.ptp(a[:, 1])])) if len(a) else 0.0
            slack = np.minimum(mm / scale, 0.01 * span) if span > 0 else mm / scale
        out[k] = slack
    return out


def _tolerance_band(vpart: Part, face_loops: dict[int, list[np.ndarray]]) -> tuple[np.ndarray, ...]:
    """What ``_trim_kernels.in_tolerance`` needs besides the loops: ``face_tol (F, 8)``
    (the face's largest edge tolerance t in mm, 0 where it is within :data:`TRIM_SLACK_MM`;
    the uv distance OCC classifies at t, the larger of the surface's u and v resolutions;
    the face's uv bounds u0, u1, v0, v1, outside which OCC's intersector finds no hit at
    all; the start and height of its segment bands along x), ``face_seg (F, 2)`` (first
    band and number of bands of its 3D edge segments) and the segments ``seg (S, 6)`` (the
    part's edge polylines, view frame), ``seg_ptr``, ``seg_members`` bucketed per face in
    bands of x widened by t.

    OCC's ray cast (IntCurvesFace_Intersector, boundary tolerance on) counts a hit outside
    a face's trim curves as on the face when it is within that uv distance of them and
    within t in space of one of the face's edge curves. trj8's faces carry edges of
    0.2-0.95 mm: their neighbours overlap them within that band, and which face answers
    there is OCC's classification. (A band point beyond the face's uv bounds is not seen by
    OCC: trj8's face 122 ends at u = 0.7320715, and a point 0.012 mm outside its loop at
    u = 0.732083 was left to the face beside, 4e-5 mm lower.)
    """
    F = len(vpart.faces)
    face_tol = np.zeros((F, 8))
    face_tol[:, 7] = 1.0
    face_seg = np.zeros((F, 2), dtype=np.int64)
    wide = []
    originals = None
    for k, lps in face_loops.items():
        f = vpart.faces[k]
        t3 = float(getattr(f, "tolerance", 0.0))
        if lps and f.topo is not None and np.isfinite(t3) and t3 > TRIM_SLACK_MM:
            from OCP.BRepAdaptor import BRepAdaptor_Surface

            if originals is None:
                originals = _occ_faces(vpart.shape)
            ad = BRepAdaptor_Surface(f.topo, True)  # restricted to the face's uv bounds
            bounds = (ad.FirstUParameter(), ad.LastUParameter(), ad.FirstVParameter(), ad.LastVParameter())
            res = max(ad.UResolution(t3), ad.VResolution(t3))
            orig = originals[f.index] if f.index < len(originals) else None
            if orig is not None and not orig.IsSame(f.topo):
                # a converted face (plane, cylinder...): OCC classifies on the original
                # surface, whose resolution a B-spline's pole bound underestimates (trj8's
                # plane 135: 0.119 for 0.168); its parameters map linearly on ours
                ao = BRepAdaptor_Surface(orig, True)
                su = (bounds[1] - bounds[0]) / max(ao.LastUParameter() - ao.FirstUParameter(), 1e-300)
                sv = (bounds[3] - bounds[2]) / max(ao.LastVParameter() - ao.FirstVParameter(), 1e-300)
                res = max(ao.UResolution(t3) * su, ao.VResolution(t3) * sv)
            face_tol[k, :6] = (t3, res, *bounds)
            wide.append(k)
    by_face: dict[int, list[np.ndarray]] = {k: [] for k in wide}
    for e in vpart.edges:
        pts = np.asarray(e.points, dtype=np.float64)
        if len(pts) < 2:
            continue
        for k in set(e.faces):
            if k in by_face:
                by_face[k].append(np.hstack([pts[:-1], pts[1:]]))
    segs, counts_l, members_l = [], [], []
    n_seg = n_bands = 0
    for k in wide:
        sk = np.concatenate(by_face[k]) if by_face[k] else np.zeros((0, 6))
        if not len(sk):
            face_tol[k, 0] = 0.0  # no edge curves known: the loops' slack only
            continue
        t3 = face_tol[k, 0]
        lo = np.minimum(sk[:, 0], sk[:, 3]) - t3
        hi = np.maximum(sk[:, 0], sk[:, 3]) + t3
        nb = int(min(max(len(sk) // 2, 1), 4096))
        h = (hi.max() - lo.min()) / nb if hi.max() > lo.min() else 1.0
        counts, members = _bucket(lo, hi, float(lo.min()), h, nb)
        face_tol[k, 6:] = lo.min(), h
        face_seg[k] = n_bands, nb
        segs.append(sk)
        counts_l.append(counts)
        members_l.append(members + n_seg)
        n_seg += len(sk)
        n_bands += nb
    if not segs:
        return face_tol, face_seg, np.zeros((0, 6)), np.zeros(1, dtype=np.int64), np.zeros(0, dtype=np.int64)
    seg_ptr = np.concatenate([[0], np.cumsum(np.concatenate(counts_l))]).astype(np.int64)
    return (face_tol, face_seg, np.ascontiguousarray(np.concatenate(segs)), seg_ptr,
            np.ascontiguousarray(np.concatenate(members_l)).astype(np.int64))


def _with_band(trim: tuple[np.ndarray, ...], band: tuple[np.ndarray, ...]) -> tuple[np.ndarray, ...]:
    """:func:`_trim_bands`' arrays carrying :func:`_tolerance_band`'s too, as
    ``_trim_kernels.in_tolerance`` reads them: the segments appended to ``edges`` (6
    columns), their bands to ``band_ptr``/``band_edges``, each face's first segment band and
    count as ``face_bi[:, 2:4]`` and its tolerance, uv distance, uv bounds and segment band
    start and height as ``face_bf[:, 3:11]``."""
    edges, band_ptr, band_edges, face_bi, face_bf = trim
    face_tol, face_seg, seg, seg_ptr, seg_members = band
    E, B = len(edges), len(band_ptr) - 1
    edges = np.vstack([edges, seg])  # loop rows: ua, va, ub, vb, slack, bulge; segment rows: x0 .. z1
    band_ptr = np.concatenate([band_ptr, band_ptr[-1] + seg_ptr[1:]]).astype(np.int64)
    band_edges = np.concatenate([band_edges, seg_members + E]).astype(np.int64)
    face_seg = np.where(face_seg[:, 1:] > 0, face_seg + np.array([B, 0]), 0)
    return (np.ascontiguousarray(edges), band_ptr, band_edges, np.ascontiguousarray(np.hstack([face_bi, face_seg])),
            np.ascontiguousarray(np.hstack([face_bf, face_tol])))


def _occ_faces(shape: Any) -> list:
    """The faces of an OCP shape in ``TopExp.MapShapes`` order (``Face.index`` order); [] for None."""
    if shape is None:
        return []
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopExp import TopExp
    from OCP.TopoDS import TopoDS
    from OCP.TopTools import TopTools_IndexedMapOfShape

    fmap = TopTools_IndexedMapOfShape()
    TopExp.MapShapes_s(shape, TopAbs_FACE, fmap)
    return [TopoDS.Face_s(fmap.FindKey(i)) for i in range(1, fmap.Extent() + 1)]


def _bucket(lo: np.ndarray, hi: np.ndarray, vlo: float, h: float, nb: int) -> tuple[np.ndarray, np.ndarray]:
    """Items with ranges ``[lo, hi]`` in ``nb`` bands of height ``h`` from ``vlo``: the count per
    band and the items band by band (each listed in every band its range meets)."""
    b0 = np.clip(np.floor((lo - vlo) / h), 0, nb - 1).astype(np.int64)
    b1 = np.clip(np.floor((hi - vlo) / h), 0, nb - 1).astype(np.int64)
    span = b1 - b0 + 1
    eid = np.repeat(np.arange(len(lo)), span)
    start = np.repeat(np.cumsum(span) - span, span)
    band = np.repeat(b0, span) + (np.arange(len(eid)) - start)
    order = np.argsort(band, kind="stable")
    return np.bincount(band, minlength=nb), eid[order]


def _trim_bands(face_loops: dict[int, list[np.ndarray]], domain: np.ndarray, F: int,
                slack_uv: dict[int, np.ndarray] | None = None,
                reach_uv: dict[int, float] | None = None,
                bulge_uv: dict[int, np.ndarray] | None = None) -> tuple[np.ndarray, ...]:
    """Trim loop edges of every face bucketed in bands of v (see ``_trim_kernels.point_in_bands``).

    ``slack_uv[k]`` (optional, one value per loop edge of face k, from
    :func:`_trim_slack_uv`) widens face k's loops: points that close to an edge count as
    inside. ``reach_uv[k]`` (optional) widens the bands of face k's edges, so that a
    point's band lists every edge within that uv distance of it (the tolerance band of
    ``_trim_kernels.in_tolerance``). ``bulge_uv[k]`` (optional, one value per loop edge)
    places face k's true trim curve beside each edge (``Face.loop_bulges``). Returns
    ``edges (E, 6)`` (ua, va, ub, vb, slack in uv, bulge in uv), ``band_ptr (B+1,),
    band_edges (X,), face_bi (F, 2), face_bf (F, 3)``.
    """
    face_bi = np.zeros((F, 2), dtype=np.int64)
    face_bf = np.zeros((F, 3))
    face_bf[:, 1] = 1.0
    edges_l, counts_l, members_l = [], [], []
    n_edges = 0
    n_bands = 0
    for k, lps in face_loops.items():
        if not lps:
            continue
        a = np.concatenate(lps)
        b = np.concatenate([np.roll(lp, -1, axis=0) for lp in lps])
        eps = 1e-9 * max(domain[k, 1] - domain[k, 0], domain[k, 3] - domain[k, 2], 1e-300)
        own = np.zeros(len(a))
        if slack_uv is not None and k in slack_uv:
            own = np.asarray(slack_uv[k], dtype=np.float64)
        bulge = np.zeros(len(a))
        if bulge_uv is not None and k in bulge_uv:
            bulge = np.asarray(bulge_uv[k], dtype=np.float64)
        e = np.hstack([a, b, np.maximum(own, eps)[:, None], bulge[:, None]])
        # an edge's band reaches its slack beyond its curve (a quarter of the bulge off the chord)
        reach = np.maximum(e[:, 4] + 0.25 * np.abs(bulge), float(reach_uv.get(k, 0.0)) if reach_uv else 0.0)
        wide = float(reach.max()) if len(e) else eps
        vlo = float(min(a[:, 1].min(), b[:, 1].min())) - wide
        vhi = float(max(a[:, 1].max(), b[:, 1].max())) + wide
        nb = int(min(max(len(e) // 2, 1), 4096))
        h = (vhi - vlo) / nb if vhi > vlo else 1.0
        counts, members = _bucket(np.minimum(e[:, 1], e[:, 3]) - reach, np.maximum(e[:, 1], e[:, 3]) + reach,
                                  vlo, h, nb)
        counts_l.append(counts)
        members_l.append(members + n_edges)
        edges_l.append(e)
        face_bi[k] = n_bands, nb
        face_bf[k] = vlo, h, eps
        n_edges += len(e)
        n_bands += nb
    if not edges_l:
        return np.zeros((0, 6)), np.zeros(1, dtype=np.int64), np.zeros(0, dtype=np.int64), face_bi, face_bf
    band_ptr = np.concatenate([[0], np.cumsum(np.concatenate(counts_l))]).astype(np.int64)
    return (np.ascontiguousarray(np.concatenate(edges_l)), band_ptr,
            np.ascontiguousarray(np.concatenate(members_l)).astype(np.int64), face_bi, face_bf)
