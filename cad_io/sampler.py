"""STEP/NURBS part to master z-map: 2D Jacobian inversion with facet fallback (paper 004 §2.1).

For every face and every grid point that one of the face's mesh triangles covers in xy,
the sampler solves ``x(u, v) = x_g, y(u, v) = y_g`` by damped Newton iteration (2D
Jacobian inversion) on the face's exact NURBS, starting from the barycentric (u, v) of the
grid point in that triangle. The start lies within the mesh deflection of the answer, so
Newton converges in two or three steps, and a face folded over itself gives one start per
layer. A solution counts when it converged, lies within ``face_zgap`` of the facet height
(no jump to another layer) and, for triangles on the mesh boundary, inside the face's trim
loops. Where Newton fails (singular Jacobian on vertical walls and folds, no convergence)
the triangle's exact barycentric height is used instead (the facet path). The top-most
candidate over all faces wins.

The ``face`` layer of the result tells which face gave each height (-1 empty), the
``method`` layer how (0 empty, 1 Jacobian inversion, 2 facet).
"""

from __future__ import annotations

import math
import os
import time
import warnings
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np

from zmap.errors import GridTooLargeError, NurbsError
from zmap.fmt import count, size
from zmap.grid import ZMap

from .part import Part
from .view import check_axis, transform_part, view_matrix

__all__ = ["EMPTY", "FACET", "JACOBIAN", "METHODS", "estimate_bytes", "grid_shape", "height_function", "sample",
           "sample_points", "summary"]

METHODS = ("auto", "jacobian", "facet")
EMPTY, JACOBIAN, FACET = 0, 1, 2
_MODE = {"auto": 0, "jacobian": 1, "facet": 2}

#: pairs (grid point, triangle) solved per kernel call; bounds the working memory and the
#: time between two checks for Ctrl-C (a kernel call cannot be interrupted)
CHUNK_PAIRS = 131_072
#: default mesh deflections as shares of the grid interval: the Newton starts need only a
#: coarse mesh (grid / START_SHARE); points answered by facets on exact faces are solved
#: again on a fine one (grid / FACET_SHARE)
START_SHARE = 1.0
FACET_SHARE = 20.0
#: bytes per pair in the working arrays (gidx 8, tri 8, w 16, z 8, status 1)
_PAIR_BYTES = 41
#: bytes per grid point kept to the end (z 8, face 4, method 1) and the map's own copy
_POINT_BYTES = 13 + 13
#: Newton: xy residual (mm) at which a solution counts as converged, and iteration cap
NEWTON_TOL = 1e-10
NEWTON_MAX_ITER = 30
#: uv lattice size for faces with a surface but no (u, v) triangulation
LATTICE = 48
#: Points this close (mm) to a face's trim loop count as inside it: the loops are polylines
#: within about 1e-4 mm of the true boundary (see _trim_slack_uv). A face whose edges carry a
#: larger tolerance in the file also holds the points OCC's ray cast counts as on it within
#: that tolerance (``_sample_kernels.in_tolerance``).
TRIM_SLACK_MM = 5e-4
#: Boundary triangles of an exact face pair with points up to this many mesh deflections
#: outside them (Newton and the trim test then decide)
BOUNDARY_MARGIN = 2.0


def _spacing(grid: Any) -> tuple[float, float]:
    if np.ndim(grid) == 0:
        dx = dy = grid
    else:
        if np.shape(grid) != (2,):
            raise ValueError(f"grid must be an interval or a pair (dx, dy), got {np.asarray(grid).tolist()!r}")
        dx, dy = grid
    try:
        dx, dy = float(dx), float(dy)
    except (TypeError, ValueError):
        raise ValueError(f"grid must be a positive number of mm, got {grid!r}") from None
    if not (math.isfinite(dx) and math.isfinite(dy) and dx > 0 and dy > 0):
        raise ValueError(f"grid intervals must be positive and finite, got dx={dx!r}, dy={dy!r}")
    return dx, dy


def _view_bounds(part: Part, axis: str) -> tuple[float, float, float, float]:
    b = np.array([f.bbox for f in part.faces], dtype=np.float64).reshape(-1, 6)
    R = view_matrix(axis)
    lo = b[:, :3] @ R.T
    hi = b[:, 3:] @ R.T
    both = np.concatenate([lo, hi])
    if not np.isfinite(both[:, :2]).any():
        raise ValueError(f"part {part.source!r} has no face with a bounding box; pass bounds=")
    return (float(np.nanmin(both[:, 0])), float(np.nanmin(both[:, 1])),
            float(np.nanmax(both[:, 0])), float(np.nanmax(both[:, 1])))


def grid_shape(bounds: Sequence[float], dx: float, dy: float) -> tuple[int, int]:
    """Grid points ``(nx, ny)`` that cover ``bounds = (x0, y0, x1, y1)``, at least 2 along each axis.

    The last grid line is the first one at or beyond ``x1`` (``y1``), within 1e-9 of an
    interval: ``x0 + (nx - 1) * dx >= x1``, so no part of the domain is left off the map
    (a domain that is a whole number of intervals keeps its last line on ``x1``).

    Examples
    --------
    >>> grid_shape((0.0, 0.0, 10.0, 5.0), 1.0, 1.0), grid_shape((0.0, 0.0, 10.2, 5.0), 1.0, 1.0)
    ((11, 6), (12, 6))
    """
    x0, y0, x1, y1 = (float(v) for v in bounds)
    if not all(math.isfinite(v) for v in (x0, y0, x1, y1)) or x1 < x0 or y1 < y0:
        raise ValueError(f"bounds must be finite (x0, y0, x1, y1) with x1 >= x0 and y1 >= y0, got {tuple(bounds)}")
    nx = max(2, int(math.ceil((x1 - x0) / dx - 1e-9)) + 1)
    ny = max(2, int(math.ceil((y1 - y0) / dy - 1e-9)) + 1)
    return nx, ny


def _centred(lo: float, hi: float, step: float, n: int) -> float:
    """First grid line of ``n`` lines ``step`` apart centred on ``[lo, hi]`` (they cover it)."""
    return 0.5 * (lo + hi) - 0.5 * (n - 1) * step


def estimate_bytes(nx: int, ny: int) -> int:
    """Working memory of :func:`sample` on an ``nx`` x ``ny`` grid, bytes (meshes excluded)."""
    n = int(nx) * int(ny)
    return n * _POINT_BYTES + min(2 * n, CHUNK_PAIRS) * _PAIR_BYTES


def _available_bytes() -> int:
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return 8 * 1024**3


def _check_memory(nx: int, ny: int) -> int:
    need = estimate_bytes(nx, ny)
    avail = _available_bytes()
    if need > 0.8 * avail:
        raise GridTooLargeError(
            f"grid of {count(nx)} x {count(ny)} = {count(nx * ny)} points needs about {size(need)}, "
            f"more than 80% of the {size(avail)} of memory available; "
            f"use a coarser grid or smaller bounds")
    return need


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


def _loop_bulges(face, lps: list[np.ndarray]) -> np.ndarray | None:
    """Per loop edge of ``face`` (its loops of 3 points or more) the bulge of the true trim
    curve beside it (``Face.loop_bulges``); None where not known (geomdl input)."""
    bulges = list(getattr(face, "loop_bulges", None) or [])
    if len(bulges) != len(lps) or any(len(b) != len(lp) for b, lp in zip(bulges, lps)):
        return None
    keep = [np.asarray(b, dtype=np.float64) for b, lp in zip(bulges, lps) if len(lp) >= 3]
    return np.concatenate(keep) if keep else None


def _trim_slack_uv(packed, face_loops: dict[int, list[np.ndarray]], F: int,
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
    """What ``_sample_kernels.in_tolerance`` needs besides the loops: ``face_tol (F, 8)``
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


def _with_band(trim: tuple, band: tuple) -> tuple:
    """:func:`_trim_bands`' arrays carrying :func:`_tolerance_band`'s too, as
    ``_sample_kernels.in_tolerance`` reads them: the segments appended to ``edges`` (6
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


def _occ_faces(shape) -> list:
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
    """Trim loop edges of every face bucketed in bands of v (see ``_sample_kernels.point_in_bands``).

    ``slack_uv[k]`` (optional, one value per loop edge of face k, from
    :func:`_trim_slack_uv`) widens face k's loops: points that close to an edge count as
    inside. ``reach_uv[k]`` (optional) widens the bands of face k's edges, so that a
    point's band lists every edge within that uv distance of it (the tolerance band of
    ``_sample_kernels.in_tolerance``). ``bulge_uv[k]`` (optional, one value per loop edge)
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


def _mesh_errors(packed, meshes: dict[int, Any]) -> dict[int, float]:
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


def _lattice_mesh(surface, n: int):
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


def _in_window(b, window: Sequence[float] | None) -> bool:
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


def _run_pairs(fs: _FaceSet, counts: np.ndarray, fill, solve, zflat: np.ndarray, fflat: np.ndarray,
               mflat: np.ndarray, update=None) -> int:
    """Fill, solve and reduce the pairs of every triangle, at most CHUNK_PAIRS at a time.

    ``counts`` (M,) pairs per triangle; ``fill(t, offsets, gidx, tri, w)`` and
    ``solve(gidx, tri, w, z, status)`` are the grid or scattered-point kernels. Returns the
    number of pairs.
    """
    from . import _sample_kernels as K

    cum = np.concatenate([[0], np.cumsum(counts)])
    n_pairs = int(cum[-1])
    t = 0
    M = len(counts)
    while t < M:
        # triangles t..t1-1 hold at most CHUNK_PAIRS pairs (or one triangle)
        t1 = int(np.searchsorted(cum, cum[t] + CHUNK_PAIRS, side="right")) - 1
        t1 = min(max(t1, t + 1), M)
        offsets = np.ascontiguousarray(cum[t:t1 + 1] - cum[t])
        P = int(offsets[-1])
        if P:
            gidx = np.empty(P, dtype=np.int64)
            tri_p = np.empty(P, dtype=np.int64)
            w = np.empty((P, 2))
            fill(t, offsets, gidx, tri_p, w)
            zc = np.empty(P)
            st = np.empty(P, dtype=np.int8)
            solve(gidx, tri_p, w, zc, st)
            K.reduce_pairs(gidx, tri_p, fs.tri_face, zc, st, zflat, fflat, mflat)
            if update is not None:
                update(P)
        t = t1
    return n_pairs


def summary(zm: ZMap) -> dict:
    """Counts and shares of the ``method`` layer of a sampled map.

    Returns
    -------
    dict
        ``points``, ``jacobian``, ``facet``, ``empty`` (counts) and ``share_jacobian``,
        ``share_facet``, ``share_empty`` (fractions of all grid points).
    """
    m = zm.layers.get("method")
    n = zm.z.size
    if m is None:
        filled = int(np.isfinite(zm.z).sum())
        counts = {"jacobian": 0, "facet": 0, "empty": n - filled}
    else:
        bc = np.bincount(np.asarray(m, dtype=np.int64).ravel(), minlength=3)
        counts = {"jacobian": int(bc[JACOBIAN]), "facet": int(bc[FACET]), "empty": int(bc[EMPTY])}
    out = {"points": n, **counts}
    for k in ("jacobian", "facet", "empty"):
        out[f"share_{k}"] = counts[k] / n if n else 0.0
    return out


def sample(part: Part, grid: float | tuple[float, float], *, bounds: Sequence[float] | None = None,
           method: str = "auto", axis: str = "+z", deflection: float | None = None,
           progress: bool = False) -> ZMap:
    """Master z-map of a part: top-most height at every grid point, seen from ``axis``.

    Parameters
    ----------
    part : cad_io.Part
        From :func:`cad_io.read_step` or :func:`cad_io.from_geomdl`. Faces without a mesh
        fine enough are (re)triangulated with :func:`cad_io.triangulate` (this sets
        ``face.mesh`` on ``part``).
    grid : float or (float, float)
        Grid interval in mm, or ``(dx, dy)``.
    bounds : (x0, y0, x1, y1), optional
        Domain in the view frame, mm; default the extents of the part's triangulation seen
        from ``axis`` (its bounding box without OCC's tolerance padding).
        Grid points are ``x0 + i*dx``, ``y0 + j*dy`` up to the first line at or beyond
        ``x1``, ``y1`` (:func:`grid_shape`), so the map covers the whole domain; on the
        default domain the lines are centred on the part's extents instead.
    method : {'auto', 'jacobian', 'facet'}
        'auto': Jacobian inversion, facets where it fails; 'jacobian': inversion only
        (points where it fails stay empty unless another face covers them); 'facet':
        barycentric heights of the mesh triangles only.
    axis : {'+z', '-z', '+x', '-x', '+y', '-y'}
        World direction that becomes the map's +z (see :mod:`cad_io.view`).
    deflection : float, optional
        Mesh deflection in mm for starts and facets. Default: a coarse mesh for the
        Newton starts (``min(dx, dy) / START_SHARE``, the grid interval), and the points
        answered by facets on exact faces solved again on a fine one (``min(dx, dy) /
        FACET_SHARE``, grid / 20) of the faces whose box holds such a point (each meshed alone;
        a face too large to mesh that fine gets OCC's exact ray cast instead: :func:`fine_cast`).
    progress : bool or tqdm bar
        Show progress: True draws a bar of the stages (meshing, sampling, facets) in
        per cent; a tqdm bar given here (``total=100``, as ``zmap convert`` opens one before
        reading the file) is carried on from where it stands.

    Returns
    -------
    ZMap
        ``z`` of shape (nx, ny), float64, mm in the view frame, NaN = no surface; layers
        ``face`` (int32, index into ``part.faces``, -1 empty) and ``method`` (int8: 0
        empty, 1 Jacobian inversion, 2 facet); ``meta`` with the source, axis, method,
        deflection, counts and seconds.

    Raises
    ------
    zmap.errors.GridTooLargeError
        The grid's arrays would not fit in the available memory (the message gives bytes).
    ValueError
        Bad ``grid``, ``bounds``, ``method`` or ``axis``, or a part without faces.

    Examples
    --------
    >>> from pathlib import Path
    >>> import cad_io
    >>> part = cad_io.read_step(Path(cad_io.__file__).parents[1] / "data" / "boss.step")
    >>> zm = sample(part, 1.0)
    >>> zm.shape, round(float(np.nanmax(zm.z)), 9), summary(zm)["share_jacobian"]
    ((81, 61), 22.0, 1.0)
    """
    from . import _sample_kernels as K

    t_start = time.perf_counter()
    if method not in _MODE:
        raise ValueError(f"method={method!r} is not one of {', '.join(repr(m) for m in METHODS)}")
    check_axis(axis)
    dx, dy = _spacing(grid)
    if not part.faces:
        raise ValueError(f"part {part.source!r} has no faces")
    default_bounds = bounds is None
    if default_bounds:
        bounds = _view_bounds(part, axis)
    elif np.shape(bounds) != (4,):
        raise ValueError(f"bounds must be (x0, y0, x1, y1), got {np.asarray(bounds).tolist()!r}")
    x0, y0 = float(bounds[0]), float(bounds[1])
    nx, ny = grid_shape(bounds, dx, dy)
    need = _check_memory(nx, ny)
    fine = None
    if deflection is None:
        deflection = min(dx, dy) / START_SHARE
        fine = min(dx, dy) / FACET_SHARE
    deflection = float(deflection)
    if not (math.isfinite(deflection) and deflection > 0):
        raise ValueError(f"deflection must be positive, got {deflection!r}")
    bar, own_bar = _stage_bar(progress)

    t_mesh = time.perf_counter()
    _stage(bar, "meshing", 0.0)
    if _needs_mesh(part, deflection):
        from .mesh import triangulate

        triangulate(part, deflection)
    t_mesh = time.perf_counter() - t_mesh
    _stage(bar, "sampling", _MESH_SHARE)
    vpart = transform_part(part, axis)
    if default_bounds:
        # the triangulation's extents: on the surface, unlike the tolerance-padded bboxes
        ext = [(m.nodes[:, 0].min(), m.nodes[:, 1].min(), m.nodes[:, 0].max(), m.nodes[:, 1].max())
               for m in (f.mesh for f in vpart.faces) if m is not None and len(m.nodes)]
        if ext:
            e = np.array(ext)
            bounds = (float(e[:, 0].min()), float(e[:, 1].min()), float(e[:, 2].max()), float(e[:, 3].max()))
            nx, ny = grid_shape(bounds, dx, dy)
            need = _check_memory(nx, ny)
        # the lines cover the part's extents, centred on them: a symmetric part gives a
        # symmetric map (a whole number of intervals keeps the lines on the extents)
        x0 = _centred(bounds[0], bounds[2], dx, nx)
        y0 = _centred(bounds[1], bounds[3], dy, ny)
    window = (x0 - dx, y0 - dy, x0 + (nx - 1) * dx + dx, y0 + (ny - 1) * dy + dy)
    fs = _face_set(vpart, deflection, window)
    for msg in fs.msgs:
        warnings.warn(msg, stacklevel=2)
    F = len(vpart.faces)

    zflat = np.full(nx * ny, np.nan)
    fflat = np.full(nx * ny, -1, dtype=np.int32)
    mflat = np.zeros(nx * ny, dtype=np.int8)
    n_pairs = 0
    if fs.tris is not None:
        counts = np.zeros(len(fs.tris), dtype=np.int64)
        K.count_pairs(fs.nodes, fs.tris, fs.tri_margin, x0, y0, dx, dy, nx, ny, counts)
        mode = _MODE[method]

        def fill(t, offsets, gidx, tri_p, w):
            K.fill_pairs(fs.nodes, fs.tris, fs.tri_margin, t, offsets, x0, y0, dx, dy, nx, ny, gidx, tri_p, w)

        def solve(gidx, tri_p, w, zc, st):
            K.solve_pairs(gidx, tri_p, w, *fs.solve_args(), x0, y0, dx, dy, ny, mode, NEWTON_TOL,
                          NEWTON_MAX_ITER, zc, st)

        total = max(int(counts.sum()), 1)
        span = _SAMPLE_SHARE - _MESH_SHARE
        done = [0]

        def update(n):
            done[0] += n
            _stage(bar, "sampling", _MESH_SHARE + span * done[0] / total)

        try:
            n_pairs = _run_pairs(fs, counts, fill, solve, zflat, fflat, mflat, update)
        except BaseException:
            if own_bar:
                bar.close()
            raise
    n_refined = n_fine = 0
    if fine is not None and fine < deflection and fs.tris is not None:
        # facet answers on exact faces (Newton failed there) come from a fine mesh, as
        # they did when every face was meshed at grid / FACET_SHARE: a fine mesh of the
        # faces that may cover them only (Ventilator: 36 of 305 faces for 3 points)
        again = np.flatnonzero((mflat == FACET) & (fs.face_mode[np.maximum(fflat, 0)] == 1))
        if again.size:
            _stage(bar, "facets", _SAMPLE_SHARE)
            gx = x0 + (again // ny) * dx
            gy = y0 + (again % ny) * dy
            z2, f2, m2, n_fine = _fine_facets(part, vpart, gx, gy, fine, deflection, method, axis,
                                              fine_cast(part, fine))
            zflat[again], fflat[again], mflat[again] = z2, f2, m2
            n_refined = int(again.size)
    _stage(bar, "done", 1.0)
    if own_bar:
        bar.close()
    seconds = time.perf_counter() - t_start
    zm = ZMap(x0, y0, dx, dy, zflat.reshape(nx, ny),
              layers={"face": fflat.reshape(nx, ny), "method": mflat.reshape(nx, ny)},
              meta={"source": str(part.source), "axis": axis, "method": method, "deflection": deflection,
                    "facet_deflection": fine if fine is not None else deflection, "facet_points_refined": n_refined,
                    "facet_faces_meshed": n_fine,
                    "faces": F, "pairs": n_pairs, "seconds": round(seconds, 4), "mesh_seconds": round(t_mesh, 4),
                    "memory_estimate_bytes": need, "warnings": fs.msgs})
    zm.meta.update({k: v for k, v in summary(zm).items() if not k.startswith("share")})
    return zm


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


def _fine_enough(mesh: Any, fine: float) -> bool:
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


def _whole_fine_meshes(part: Part, faces: np.ndarray, fine: float) -> list:
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


def _face_caster(part: Part, k: int, axis: str):
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


#: where the stages of :func:`sample` end on its progress bar (shares of the bar)
_MESH_SHARE = 0.15
_SAMPLE_SHARE = 0.95


def _stage_bar(progress):
    """``(bar, owned)``: a tqdm bar given by the caller (carried on), a new one for True, None."""
    if hasattr(progress, "update") and hasattr(progress, "set_description"):
        return progress, False
    if not progress:
        return None, False
    from tqdm import tqdm

    return tqdm(total=100, unit="%", desc="meshing: ", leave=False,
                bar_format="{desc}{percentage:3.0f}%|{bar}| {elapsed}"), True


def _stage(bar, name: str, share: float) -> None:
    """Move ``bar`` (total 100) to ``share`` of the way, under the stage ``name``."""
    if bar is None:
        return
    start = getattr(bar, "_zmap_start", None)
    if start is None:
        start = float(bar.n)
        bar._zmap_start = start
    target = start + (100.0 - start) * min(max(share, 0.0), 1.0)
    if bar.desc != name + ": ":
        bar.set_description_str(name + ": ", refresh=True)  # every stage is drawn, however short
    if target > bar.n:
        bar.update(target - bar.n)


def _ids(ids: list[int], limit: int = 20) -> str:
    s = ", ".join(str(i) for i in ids[:limit])
    return s + (f", ... ({len(ids) - limit} more)" if len(ids) > limit else "")


# ---- scattered points -------------------------------------------------------------------------

#: default mesh deflection (mm) of :func:`sample_points`: starts and facet fallback heights
POINTS_DEFLECTION = 0.01
#: scattered points solved per pass of :func:`sample_points` (bounds its working memory)
POINTS_CHUNK = 1_000_000
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


def _bins(px: np.ndarray, py: np.ndarray, fs: _FaceSet) -> tuple:
    """Square bins over the points, CSR lists of the points in each (see ``count_pairs_xy``)."""
    n = len(px)
    bx0, by0 = float(px.min()), float(py.min())
    wx, wy = float(px.max()) - bx0, float(py.max()) - by0
    # about one point per bin, but no bin much smaller than a typical triangle
    e = fs.nodes[fs.tris[:, 1], :2] - fs.nodes[fs.tris[:, 0], :2]
    tri_len = float(np.median(np.hypot(e[:, 0], e[:, 1]))) if len(e) else 1.0
    bh = max(math.sqrt(max(wx * wy, 1e-12) / max(n, 1)), 0.25 * tri_len, 1e-6)
    while (wx / bh + 1) * (wy / bh + 1) > 4 * n + 16:
        bh *= 1.5
    nbx = int(wx / bh) + 1
    nby = int(wy / bh) + 1
    key = np.minimum(((px - bx0) / bh).astype(np.int64), nbx - 1) * nby + np.minimum(
        ((py - by0) / bh).astype(np.int64), nby - 1)
    order = np.argsort(key, kind="stable").astype(np.int64)
    ptr = np.zeros(nbx * nby + 1, dtype=np.int64)
    np.cumsum(np.bincount(key, minlength=nbx * nby), out=ptr[1:])
    return bx0, by0, bh, nbx, nby, ptr, order


def sample_points(part: Part, x, y, *, deflection: float | None = None, method: str = "auto",
                  axis: str = "+z") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact top-most heights of a part at scattered xy (the grid sampler's method per point).

    Every mesh triangle that covers a point in xy gives a start for the 2D Jacobian
    inversion on its face's NURBS, with the trim test and facet fallback of :func:`sample`
    (the same kernel solves both); the top-most candidate wins.

    Parameters
    ----------
    part : cad_io.Part
        Meshed on first use at ``deflection``; the packed faces are cached on the part per
        deflection and axis, so repeated calls pay only for the points.
    x, y : array_like of float, broadcastable
        World (view-frame) coordinates in mm.
    deflection : float, optional
        Mesh deflection in mm for starts and facet heights; default
        :data:`POINTS_DEFLECTION` (0.01).
    method : {'auto', 'jacobian', 'facet'}
        As in :func:`sample`.
    axis : str
        View axis, as in :func:`sample`.

    Returns
    -------
    z : ndarray of float64 (broadcast shape)
        Heights in mm, NaN where no face covers the point (or for NaN input).
    face : ndarray of int32
        Face index that gave each height, -1 where none.
    method : ndarray of int8
        0 empty, 1 Jacobian inversion, 2 facet.

    Examples
    --------
    >>> from pathlib import Path
    >>> import cad_io
    >>> part = cad_io.read_step(Path(cad_io.__file__).parents[1] / "data" / "boss.step")
    >>> z, face, how = sample_points(part, [-15.0, 22.0, 100.0], [5.0, -12.0, 0.0])
    >>> z.round(9).tolist(), how.tolist()
    ([22.0, 16.0, nan], [1, 1, 0])
    """
    from . import _sample_kernels as K

    if method not in _MODE:
        raise ValueError(f"method={method!r} is not one of {', '.join(repr(m) for m in METHODS)}")
    check_axis(axis)
    if not part.faces:
        raise ValueError(f"part {part.source!r} has no faces")
    deflection = POINTS_DEFLECTION if deflection is None else float(deflection)
    if not (math.isfinite(deflection) and deflection > 0):
        raise ValueError(f"deflection must be positive, got {deflection!r}")
    xb, yb = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
    shape = xb.shape
    px = np.ascontiguousarray(xb).ravel()
    py = np.ascontiguousarray(yb).ravel()
    n = px.size
    zflat = np.full(n, np.nan)
    fflat = np.full(n, -1, dtype=np.int32)
    mflat = np.zeros(n, dtype=np.int8)
    good = np.flatnonzero(np.isfinite(px) & np.isfinite(py))
    fs = _cached_face_set(part, deflection, axis)
    if fs.tris is None:
        return zflat.reshape(shape), fflat.reshape(shape), mflat.reshape(shape)
    mode = _MODE[method]
    # points in chunks: the bins and working arrays take ~100 bytes a point, and an EZ-map
    # asks for all its e-points at once (bm2_ec_t4-A: 8 GB in one call before chunking)
    for c0 in range(0, good.size, POINTS_CHUNK):
        sel = good[c0:c0 + POINTS_CHUNK]
        gx = np.ascontiguousarray(px[sel])
        gy = np.ascontiguousarray(py[sel])
        bins = _bins(gx, gy, fs)
        counts = np.zeros(len(fs.tris), dtype=np.int64)
        K.count_pairs_xy(fs.nodes, fs.tris, fs.tri_margin, gx, gy, *bins, counts)

        def fill(t, offsets, gidx, tri_p, w, gx=gx, gy=gy, bins=bins):
            K.fill_pairs_xy(fs.nodes, fs.tris, fs.tri_margin, t, offsets, gx, gy, *bins, gidx, tri_p, w)

        def solve(gidx, tri_p, w, zc, st, gx=gx, gy=gy):
            K.solve_pairs_xy(gidx, tri_p, w, *fs.solve_args(), gx, gy, mode, NEWTON_TOL, NEWTON_MAX_ITER, zc, st)

        zg = np.full(sel.size, np.nan)
        fg = np.full(sel.size, -1, dtype=np.int32)
        mg = np.zeros(sel.size, dtype=np.int8)
        _run_pairs(fs, counts, fill, solve, zg, fg, mg)
        zflat[sel] = zg
        fflat[sel] = fg
        mflat[sel] = mg
    return zflat.reshape(shape), fflat.reshape(shape), mflat.reshape(shape)


def height_function(part: Part, **kwargs: Any) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """``heights(x, y) -> z``: the part's top-most heights as the refinement steps take them.

    Parameters
    ----------
    part : cad_io.Part
    **kwargs
        ``deflection``, ``method``, ``axis`` of :func:`sample_points`.

    Returns
    -------
    callable
        ``heights(x, y)`` returns float64 heights (broadcast shape), NaN where there is no
        surface. Its attribute ``last_method`` holds the method codes of the latest call, so a
        caller can count facet answers (code 2).

    Examples
    --------
    >>> from pathlib import Path
    >>> import cad_io
    >>> part = cad_io.read_step(Path(cad_io.__file__).parents[1] / "data" / "pocket.step")
    >>> h = height_function(part)
    >>> h(np.array([0.0]), np.array([0.0])).round(9).tolist()
    [15.0]
    """
    unknown = set(kwargs) - {"deflection", "method", "axis"}
    if unknown:
        raise TypeError(f"height_function got unexpected options {sorted(unknown)}; "
                        f"it takes 'deflection', 'method', 'axis'")

    def heights(x, y):
        z, _face, how = sample_points(part, x, y, **kwargs)
        heights.last_method = how
        return z

    heights.last_method = np.zeros(0, dtype=np.int8)
    heights.part = part
    return heights
