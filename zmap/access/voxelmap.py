"""The visibility voxel map of paper 002 and what it answers, without the CAD kernel.

Pipeline (paper §4.2, steps 1-4):

1. :meth:`VoxelMap.from_samples`: surface samples (point, outward normal, largest concave
   curvature, face id, area weight) at a step d' << d are binned into voxels of edge d. Per
   boundary voxel: ``V'_l`` = AND of ``H_V(t)`` over its samples, ``L'`` = OR of ``H_L(t)``, the
   largest curvature, the surface id (-1 where several faces meet), a crease flag.
2. Paint spreading (:func:`paint`) splits the other voxels into exterior (reached from the
   grid's border without crossing a boundary voxel) and interior, with the paper's model
   checks: boundary voxels edge-connected, one outward side per surface. A part that fails
   raises :class:`AccessModelError` naming the faces and where.
3. :func:`global_visibility`: ``V'_g`` by cylinder casting.
4. :func:`accessibility`: the ball-end map ``A'`` (three conditions over ``E_n(v)``), with
   shank and holder cylinders; :func:`three_axis`, :func:`set_cover` and
   :func:`node_directions` turn it into answers.

Examples
--------
>>> import numpy as np
>>> from zmap.access.voxelmap import VoxelMap
>>> rng = np.random.default_rng(0)
>>> p = rng.normal(size=(20000, 3)); p /= np.linalg.norm(p, axis=1)[:, None]
>>> vm = VoxelMap.from_samples(10 * p, p, np.full(len(p), -0.1), np.zeros(len(p), int),
...                            np.full(len(p), 0.06), d=1.0, q=2)
>>> vm.n_interior > 0 and vm.n_boundary > 0
True
"""

from __future__ import annotations

import os
import re
import tempfile
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import ZMapError
from .directions import DirectionSet, count, direction_set, from_bool, to_bool

__all__ = ["AccessModelError", "VoxelMap", "Tool", "parse_tool", "parse_holder", "paint",
           "global_visibility", "accessibility", "tool_clearance", "three_axis", "set_cover", "node_directions",
           "AccessResult"]

EXTERIOR, BOUNDARY, INTERIOR, UNPAINTED = 0, 1, 2, 3
#: Largest number of voxels a map may hold (about 1 GB of state and index arrays).
MAX_VOXELS = 200_000_000


class AccessModelError(ZMapError, ValueError):
    """A part whose voxel model fails the paper's checks (open shell, pieces, faces with two
    outward sides) or an access request that cannot be answered (bad d, d', q or tool)."""


@dataclass
class Tool:
    """A ball-end cutter with its shank and an optional holder.

    Parameters
    ----------
    diameter : float
        Ball (and shank) diameter, mm.
    stickout : float
        Distance from the tool tip to the holder's face, mm (ignored without a holder).
    holder_diameter, holder_length : float
        Holder cylinder, mm; 0 for none. The shank and the holder are tested as reaching
        upward without end (the spindle above them), which is conservative.
    """

    diameter: float
    stickout: float = 25.0
    holder_diameter: float = 0.0
    holder_length: float = 0.0

    def __post_init__(self) -> None:
        for name in ("diameter", "stickout", "holder_diameter", "holder_length"):
            v = float(getattr(self, name))
            if not np.isfinite(v) or v < 0 or (name == "diameter" and v == 0):
                raise AccessModelError(f"tool {name} must be a positive number of mm, got {v!r}")
            setattr(self, name, v)
        if self.holder_diameter and self.holder_diameter < self.diameter:
            raise AccessModelError(f"holder diameter {self.holder_diameter:g} mm is smaller than the "
                                   f"tool diameter {self.diameter:g} mm")
        if self.holder_diameter and self.stickout <= self.diameter / 2:
            raise AccessModelError(f"stick-out {self.stickout:g} mm must exceed the ball radius "
                                   f"{self.diameter / 2:g} mm")

    @property
    def radius(self) -> float:
        return self.diameter / 2.0


def parse_tool(spec: str) -> float:
    """Ball diameter (mm) from ``'ball:6'``.

    Examples
    --------
    >>> parse_tool("ball:6")
    6.0
    """
    m = re.fullmatch(r"\s*ball:([0-9.eE+-]+)\s*", str(spec))
    try:
        value = float(m.group(1)) if m else float("nan")
    except ValueError:
        value = float("nan")
    if not m or not np.isfinite(value) or value <= 0:
        raise AccessModelError(f"tool {spec!r} is not 'ball:DIAMETER' with a positive diameter in mm "
                               "(only ball-end cutters are supported)")
    return value


def parse_holder(spec: str) -> tuple[float, float]:
    """``(diameter, length)`` in mm from ``'20x40'``.

    Examples
    --------
    >>> parse_holder("20x40")
    (20.0, 40.0)
    """
    m = re.fullmatch(r"\s*([0-9.eE+-]+)\s*[xX]\s*([0-9.eE+-]+)\s*", str(spec))
    try:
        dia, length = (float(m.group(1)), float(m.group(2))) if m else (np.nan, np.nan)
    except ValueError:
        dia, length = np.nan, np.nan
    if not m or not (dia > 0 and length > 0 and np.isfinite(dia) and np.isfinite(length)):
        raise AccessModelError(f"holder {spec!r} is not 'DIAMETERxLENGTH' in mm, e.g. '20x40'")
    return dia, length


@dataclass
class Pieces:
    """The faces of the voxels where several faces meet, one piece per (voxel, face): the
    casting's blockers there, so that an edge voxel blocks as its faces do, not as the box
    around them (which holds the empty corner of a convex edge) with the light set of all.

    Attributes
    ----------
    voxel : ndarray of shape (np,), int64
        Boundary voxel of each piece.
    lo, hi : ndarray of shape (np, 3), float64
        The piece's box (its samples' box grown as ``VoxelMap.tight_lo``, clipped to the voxel).
    light : ndarray of shape (np, words), uint64
        ``L'`` of the piece's samples.
    point, normal, slab :
        Mean point (np, 3), unit mean normal (np, 3) and half-thickness (np,) of the piece
        about that plane, as ``VoxelMap.slab``.
    face : ndarray of shape (np,), int64
        The piece's face.
    vl : ndarray of shape (np, words), uint64
        ``V'_l`` of the piece's samples: the casting's query for the piece's own visibility
        (:func:`global_visibility` with ``pieces=True``), which a point of that face in the
        voxel has, rather than the voxel's (the AND over all its faces).
    octant : ndarray of shape (np,), int64, optional
        Only in ``VoxelMap.fine`` (the half-voxel pieces): the half-voxel cell of the piece in
        its voxel, ``(2 a + b) 2 + c`` for the cell's offsets (a, b, c) in {0, 1} along x, y, z;
        ``lo``, ``hi`` are then clipped to that cell, and ``light`` has no words (the fine
        pieces are queries, never blockers).
    """

    voxel: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    light: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    slab: np.ndarray
    face: np.ndarray | None = None
    vl: np.ndarray | None = None
    octant: np.ndarray | None = None


@dataclass
class VoxelMap:
    """The visibility voxel map M' (paper 002 §4.3-4.4).

    Attributes
    ----------
    origin : ndarray of shape (3,), float64
        Corner of voxel (0, 0, 0), mm.
    d : float
        Voxel edge, mm.
    state : ndarray of shape (nx, ny, nz), uint8
        0 exterior, 1 boundary, 2 interior.
    index : ndarray of shape (nx, ny, nz), int32
        Boundary voxel number, -1 elsewhere.
    ijk : ndarray of shape (mb, 3), int32
        Grid indices of the boundary voxels.
    vl, light : ndarray of shape (mb, words), uint64
        ``V'_l`` and ``L'`` bitsets.
    curvature : ndarray of shape (mb,), float64
        Largest concave principal curvature of the samples (1/mm; negative where convex).
    surface : ndarray of shape (mb,), int32
        Face id, -1 where samples of several faces meet.
    crease : ndarray of shape (mb,), bool
        Several faces meet with normals more than ``crease_deg`` apart.
    point, normal : ndarray of shape (mb, 3), float64
        Mean sample point and unit mean normal.
    area : ndarray of shape (mb,), float64
        Surface area sampled in the voxel, mm^2.
    q : int
        Frequency of the direction set.
    box_lo, box_hi : ndarray of shape (mb, 3), float64
        Box of the surface inside each boundary voxel (its samples' box grown by d', clipped
        to the voxel): the ray origins of the casting and the blockers of the tool tests.
    tight_lo, tight_hi : ndarray of shape (mb, 3), float64
        The same grown per axis only as far as the surface can run past its samples (d'
        times the largest sine of its normals to the axis: 1e-6 d' across a flat face square
        to the axis): where one face crosses the voxel, the blockers of the casting, and grown
        to at least d' within the voxel, the casting's cylinders.
    pieces : Pieces
        Where several faces cross a voxel, the casting's blockers: one per face.
    fine : Pieces
        One piece per face and half-voxel cell (edge d / 2) of every boundary voxel, with
        ``octant``: the queries of the refinement of :func:`global_visibility` (``refine=True``).
    slab : ndarray of shape (mb,), float64
        Half-thickness of the surface patch about the plane through ``point`` with normal
        ``normal``: every patch point x has ``(x - point) . normal >= -slab`` (inf: unknown).
        The casting starts each line of the cylinder no lower than that (see
        :func:`global_visibility`).
    flipped : list of int
        Faces whose normals pointed inward and were turned (the paper's SIGN = -1).
    """

    origin: np.ndarray
    d: float
    state: np.ndarray
    index: np.ndarray
    ijk: np.ndarray
    vl: np.ndarray
    light: np.ndarray
    curvature: np.ndarray
    surface: np.ndarray
    crease: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    area: np.ndarray
    q: int
    flipped: list = field(default_factory=list)
    step: float = float("nan")
    n_samples: int = 0
    box_lo: np.ndarray | None = None
    box_hi: np.ndarray | None = None
    slab: np.ndarray | None = None
    tight_lo: np.ndarray | None = None
    tight_hi: np.ndarray | None = None
    pieces: Pieces | None = None
    fine: Pieces | None = None

    @property
    def directions(self) -> DirectionSet:
        return direction_set(self.q)

    @property
    def n_boundary(self) -> int:
        return int(self.ijk.shape[0])

    @property
    def n_interior(self) -> int:
        return int(np.count_nonzero(self.state == INTERIOR))

    @property
    def n_voxels(self) -> int:
        return int(self.state.size)

    @property
    def centres(self) -> np.ndarray:
        """Boundary voxel centres (mb, 3), mm."""
        return self.origin + self.d * (self.ijk + 0.5)

    def boxes(self, *, tight: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Centres and half extents (mb, 3) of the surface boxes (``tight``: the blockers'
        boxes, the surface boxes where unknown; the voxel cubes if neither is known)."""
        lo, hi = (self.tight_lo, self.tight_hi) if tight and self.tight_lo is not None else (self.box_lo, self.box_hi)
        if lo is None:
            return self.centres, np.full((self.n_boundary, 3), 0.5 * self.d)
        return 0.5 * (lo + hi), 0.5 * (hi - lo)

    @property
    def nbytes(self) -> int:
        return int(sum(a.nbytes for a in (self.state, self.index, self.ijk, self.vl, self.light,
                                             self.curvature, self.surface, self.crease, self.point,
                                             self.normal, self.area)))

    @classmethod
    def from_samples(cls, points, normals, curvature, face, weight, *, d: float, q: int,
                     step: float | None = None, exact: bool = True, crease_deg: float = 10.0,
                     pad: int = 2, check: bool = True, fine: bool = True) -> "VoxelMap":
        """Build the map from surface samples (paper 002 §4.3 and §4.4).

        Parameters
        ----------
        points, normals : ndarray of shape (n, 3), float64
            Sample points (mm) and unit normals, outward as far as the caller knows (a face
            whose normals all point inward is turned; one that points both ways fails).
        curvature : ndarray of shape (n,), float64
            Largest concave principal curvature (1/mm), negative where convex.
        face : ndarray of shape (n,), int
            Surface id of each sample (>= 0).
        weight : ndarray of shape (n,), float64
            Area each sample stands for, mm^2.
        d : float, keyword-only
            Voxel edge, mm.
        q : int, keyword-only
            Frequency of the direction set (k = 20 q^2).
        step : float, optional
            The sampling step d' used (recorded; must be < d).
        exact : bool
            True (default): fold each sample's exact hemisphere ``{n : n . n_p > 0}`` into
            ``V'_l`` and ``L'``. False: the paper's ``H_V(t)`` / ``H_L(t)`` of the sample's tessel
            (O(k/64) per sample, but it loses about one ring of tessels at the horizon: on
            pocket.step 93 % agreement with the OCC rays against 99 %).
        crease_deg : float
            Angle between normals of different faces in one voxel above which the voxel is
            a crease (condition 3 of the accessibility map).
        check : bool
            Apply the model checks (raise :class:`AccessModelError` on failure).
        fine : bool
            Also build ``fine``, the half-voxel pieces that :func:`global_visibility` casts with
            ``refine=True`` (default True).
        """
        from ._access_kernels import (accumulate, orientation_votes, paint_exterior, patch_slab,
                                      piece_accumulate)

        d = _check_d(d)
        ds = _direction_set(q)
        if step is not None:
            step = float(step)
            if not (step > 0) or step >= d:
                raise AccessModelError(f"sampling step d' must be positive and smaller than the voxel "
                                       f"d = {d:g} mm, got d' = {step!r} mm")
        pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        nrm = np.ascontiguousarray(normals, dtype=np.float64).reshape(-1, 3)
        kmax = np.ascontiguousarray(curvature, dtype=np.float64).ravel()
        fid = np.ascontiguousarray(face, dtype=np.int64).ravel()
        wt = np.ascontiguousarray(weight, dtype=np.float64).ravel()
        n = len(pts)
        if not (len(nrm) == len(kmax) == len(fid) == len(wt) == n):
            raise ValueError(f"samples must have one row each: points {len(pts)}, normals {len(nrm)}, "
                             f"curvature {len(kmax)}, face {len(fid)}, weight {len(wt)}")
        if n == 0:
            raise AccessModelError("no surface samples: the part has no faces to voxelise")
        good = np.isfinite(pts).all(axis=1) & np.isfinite(nrm).all(axis=1)
        if not good.all():
            bad = int(np.flatnonzero(~good)[0])
            raise AccessModelError(f"sample {bad} of face {fid[bad]} is not finite: {pts[bad]}, normal {nrm[bad]}")
        kmax = np.where(np.isfinite(kmax), kmax, np.inf)
        lo = pts.min(axis=0)
        hi = pts.max(axis=0)
        origin = lo - pad * d
        shape = tuple(int(s) for s in np.floor((hi - origin) / d).astype(np.int64) + pad + 1)
        total = int(np.prod(np.array(shape, dtype=np.float64)))
        if total > MAX_VOXELS:
            raise AccessModelError(f"{shape[0]} x {shape[1]} x {shape[2]} = {total:,} voxels at d = {d:g} mm "
                                   f"exceed the limit of {MAX_VOXELS:,}: choose a larger --voxel")
        ijk = np.floor((pts - origin) / d).astype(np.int64)
        flat = (ijk[:, 0] * shape[1] + ijk[:, 1]) * shape[2] + ijk[:, 2]
        uniq, vox = np.unique(flat, return_inverse=True)
        state = np.full(shape, UNPAINTED, dtype=np.uint8)
        state.ravel()[uniq] = BOUNDARY
        index = np.full(shape, -1, dtype=np.int32)
        index.ravel()[uniq] = np.arange(len(uniq), dtype=np.int32)
        bijk = np.stack(np.unravel_index(uniq, shape), axis=1).astype(np.int32)
        paint_exterior(state)
        flipped: list[int] = []
        nf = int(fid.max()) + 1
        if check:
            _check_connected(state, index, fid, vox, pts)
            if not np.any(state == INTERIOR):
                raise AccessModelError(
                    f"no interior voxels at d = {d:g} mm: the exterior paint leaks through the "
                    f"shell (an open surface, a gap wider than {d:g} mm, or walls thinner than the "
                    "voxel); the paper needs a closed model at the voxel resolution")
            votes = np.zeros((nf, 4), dtype=np.int64)
            orientation_votes(pts, nrm, fid, origin, d, state, votes)
            flipped = _check_orientation(votes, fid, pts, nrm)
            if flipped:
                turn = np.isin(fid, flipped)
                nrm = nrm.copy()
                nrm[turn] *= -1
                kmax = np.where(turn, -kmax, kmax)  # concave and convex swap with the side
        mb = len(uniq)
        W = ds.words
        step_ = float(step) if step is not None else 0.25 * d
        # with the half-voxel pieces, the voxels' and pieces' bitsets are folded from theirs
        # (the same AND and OR over the same samples, each sample's hemisphere made once)
        fine_pieces, flight = _fine_pieces(vox, pts, nrm, fid, origin, d, bijk, step_, ds, exact) if fine else (None, None)
        mode = 2 if fine else (1 if exact else 0)
        vl = np.full((mb, W), np.uint64(0xFFFFFFFFFFFFFFFF), dtype=np.uint64)
        if ds.k % 64:
            vl[:, -1] = np.uint64((1 << (ds.k % 64)) - 1)
        light = np.zeros((mb, W), dtype=np.uint64)
        curv = np.full(mb, -np.inf)
        surf = np.full(mb, -1, dtype=np.int32)
        crease = np.zeros(mb, dtype=np.uint8)
        psum = np.zeros((mb, 3))
        nsum = np.zeros((mb, 3))
        area = np.zeros(mb)
        nsamp = np.zeros(mb, dtype=np.int64)
        first = np.zeros((mb, 3))
        pmin = np.full((mb, 3), np.inf)
        pmax = np.full((mb, 3), -np.inf)
        accumulate(np.ascontiguousarray(vox, dtype=np.int64), pts, nrm, kmax, fid, wt, ds._centres,
                   ds._frames, ds.q, ds.hv, ds.hl, mode, ds.normals, vl, light, curv,
                   surf, crease, float(np.cos(np.radians(crease_deg))), psum, nsum, area, nsamp, first, pmin,
                   pmax)
        if fine:
            fv = fine_pieces.voxel
            start = np.flatnonzero(np.r_[True, fv[1:] != fv[:-1]])
            vl[fv[start]] = np.bitwise_and.reduceat(fine_pieces.vl, start, axis=0)
            light[fv[start]] = np.bitwise_or.reduceat(flight, start, axis=0)
        point = psum / nsamp[:, None]
        nlen = np.linalg.norm(nsum, axis=1)
        normal = np.where(nlen[:, None] > 0, nsum / np.maximum(nlen, 1e-300)[:, None], 0.0)
        # the box of the surface in each voxel: its samples' box grown by d' (the surface runs
        # on past the outer samples), clipped to the voxel; and the tighter box of the blockers
        # (per axis d' times the sine of the normals to the axis: flat across a flat face)
        grow = np.empty((mb, 3))
        slab = np.empty(mb)
        patch_slab(np.ascontiguousarray(vox, dtype=np.int64), pts, nrm, point, normal, step_, slab, grow)
        vlo = origin + d * bijk
        box_lo = np.maximum(pmin - step_, vlo)
        box_hi = np.minimum(pmax + step_, vlo + d)
        tight_lo = np.maximum(pmin - grow, vlo)
        tight_hi = np.minimum(pmax + grow, vlo + d)
        # one piece per face in the voxels where several faces meet
        sel = np.flatnonzero(surf[vox] < 0)
        key = vox[sel].astype(np.int64) * (int(fid.max()) + 1) + fid[sel]
        ukey, pinv = np.unique(key, return_inverse=True)
        npc = len(ukey)
        pvox = ukey // (int(fid.max()) + 1)
        plight = np.zeros((npc, W), dtype=np.uint64)
        pvl = np.full((npc, W), np.uint64(0xFFFFFFFFFFFFFFFF), dtype=np.uint64)
        if ds.k % 64:
            pvl[:, -1] = np.uint64((1 << (ds.k % 64)) - 1)
        ps, ns = np.zeros((npc, 3)), np.zeros((npc, 3))
        pmn, pmx = np.full((npc, 3), np.inf), np.full((npc, 3), -np.inf)
        spts, snrm = np.ascontiguousarray(pts[sel]), np.ascontiguousarray(nrm[sel])
        pinv = np.ascontiguousarray(pinv, dtype=np.int64)
        piece_accumulate(pinv, spts, snrm, ds._centres, ds._frames, ds.q, ds.hv, ds.hl, mode, ds.normals,
                         pvl, plight, ps, ns, pmn, pmx)
        if fine and npc:
            # a piece's bitsets: its face's half-voxel pieces' in its voxel
            fk = fine_pieces.voxel * (int(fid.max()) + 1) + fine_pieces.face
            sel = np.flatnonzero(np.isin(fk, ukey))
            order = sel[np.argsort(fk[sel], kind="stable")]
            st = np.flatnonzero(np.r_[True, fk[order][1:] != fk[order][:-1]])
            at = np.searchsorted(ukey, fk[order][st])
            pvl[at] = np.bitwise_and.reduceat(fine_pieces.vl[order], st, axis=0)
            plight[at] = np.bitwise_or.reduceat(flight[order], st, axis=0)
        ppoint = ps / np.bincount(pinv, minlength=npc)[:, None]
        plen = np.linalg.norm(ns, axis=1)
        pnormal = np.where(plen[:, None] > 0, ns / np.maximum(plen, 1e-300)[:, None], 0.0)
        pslab, pgrow = np.empty(npc), np.empty((npc, 3))
        patch_slab(pinv, spts, snrm, ppoint, pnormal, step_, pslab, pgrow)
        pieces = Pieces(voxel=pvox, lo=np.maximum(pmn - pgrow, vlo[pvox]), hi=np.minimum(pmx + pgrow, vlo[pvox] + d),
                        light=plight, point=ppoint, normal=pnormal, slab=pslab,
                        face=(ukey % (int(fid.max()) + 1)).astype(np.int64), vl=pvl)
        return cls(origin=origin, d=d, state=state, index=index, ijk=bijk, vl=vl, light=light,
                   curvature=curv, surface=surf, crease=crease.astype(bool), point=point,
                   normal=normal, area=area, q=ds.q, flipped=flipped,
                   step=float(step) if step is not None else float("nan"), n_samples=n,
                   box_lo=box_lo, box_hi=box_hi, slab=slab, tight_lo=tight_lo, tight_hi=tight_hi,
                   pieces=pieces, fine=fine_pieces)

    def skin(self) -> np.ndarray:
        """Centres (ms, 3) of the interior voxels 26-adjacent to a non-interior voxel: every
        line from outside that enters the interior meets one of them first."""
        return self.origin + self.d * (self.skin_ijk() + 0.5)

    @property
    def sampling_step(self) -> float:
        """d' (d / 4 where the map was built without it)."""
        return float(self.step) if np.isfinite(self.step) else 0.25 * self.d

    def blockers(self) -> tuple[np.ndarray, ...]:
        """The casting's boundary blockers: the voxels crossed by one face (their tight
        boxes) and the pieces of the others (all voxels where no pieces are known).

        Returns
        -------
        centre, half : (nb, 3) box centres and half extents; voxel : (nb,) int64;
        light : (nb, words) uint64; plane : (nb, 7) mean point, unit normal and slab.
        """
        c, h = self.boxes(tight=True)
        plane = np.concatenate([self.point, self.normal, self.slabs()[:, None]], axis=1)
        if self.pieces is None:
            return c, h, np.arange(self.n_boundary, dtype=np.int64), self.light, plane
        one = np.flatnonzero(self.surface >= 0)
        p = self.pieces
        pplane = np.concatenate([p.point, p.normal, p.slab[:, None]], axis=1)
        return (np.concatenate([c[one], 0.5 * (p.lo + p.hi)]), np.concatenate([h[one], 0.5 * (p.hi - p.lo)]),
                np.concatenate([one, p.voxel]).astype(np.int64), np.concatenate([self.light[one], p.light]),
                np.concatenate([plane[one], pplane]))

    def slabs(self) -> np.ndarray:
        """``slab`` (mb,), inf where unknown (a map built without it)."""
        return np.full(self.n_boundary, np.inf) if self.slab is None else np.asarray(self.slab, dtype=np.float64)

    def skin_ijk(self) -> np.ndarray:
        """Grid indices (ms, 3) of the skin voxels of :meth:`skin`, in the same order."""
        from scipy import ndimage

        inner = self.state == INTERIOR
        core = ndimage.binary_erosion(inner, structure=np.ones((3, 3, 3), bool), border_value=0)
        return np.argwhere(inner & ~core)

    def voxel_of(self, points) -> np.ndarray:
        """Boundary voxel number of each point (-1 outside the boundary voxels)."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        ijk = np.floor((p - self.origin) / self.d).astype(np.int64)
        inside = ((ijk >= 0) & (ijk < np.array(self.state.shape))).all(axis=1)
        out = np.full(len(p), -1, dtype=np.int64)
        out[inside] = self.index[ijk[inside, 0], ijk[inside, 1], ijk[inside, 2]]
        return out


def _octant(points: np.ndarray, origin: np.ndarray, d: float, ijk: np.ndarray) -> np.ndarray:
    """The half-voxel cell ``(2 a + b) 2 + c`` (offsets a, b, c in {0, 1} along x, y, z) of
    each point in its voxel ``ijk`` (a point on the voxel's far plane rounds into it)."""
    half = np.floor(2.0 * (np.asarray(points, dtype=np.float64).reshape(-1, 3) - origin) / d).astype(np.int64)
    half = np.clip(half - 2 * np.asarray(ijk, dtype=np.int64), 0, 1)
    return (half[:, 0] * 2 + half[:, 1]) * 2 + half[:, 2]


def _octant_lo(origin: np.ndarray, d: float, ijk: np.ndarray, octant: np.ndarray) -> np.ndarray:
    """Low corner (n, 3) of half-voxel cell ``octant`` of voxel ``ijk`` (see :func:`_octant`)."""
    o = np.asarray(octant, dtype=np.int64)
    return origin + d * ijk + 0.5 * d * np.stack([o // 4, (o // 2) % 2, o % 2], axis=1)


def _fine_pieces(vox, pts, nrm, fid, origin, d, bijk, step, ds, exact) -> tuple[Pieces, np.ndarray]:
    """One piece per face and half-voxel cell of each boundary voxel (``VoxelMap.fine``): its
    samples' V'_l, mean point and normal, slab (:func:`~zmap.access._access_kernels.patch_slab`)
    and box grown as the pieces' are, clipped to the half-voxel cell; sorted by voxel, then
    cell, then face. Also their L' (n, words), which the map folds into the voxels' and
    pieces' and does not keep."""
    from ._access_kernels import piece_accumulate, patch_slab

    W = ds.words
    octant = _octant(pts, origin, d, bijk[vox])
    nf = int(fid.max()) + 1
    key = (vox.astype(np.int64) * 8 + octant) * nf + fid
    ukey, inv = np.unique(key, return_inverse=True)
    inv = np.ascontiguousarray(inv.ravel(), dtype=np.int64)
    n = len(ukey)
    vl = np.full((n, W), np.uint64(0xFFFFFFFFFFFFFFFF), dtype=np.uint64)
    if ds.k % 64:
        vl[:, -1] = np.uint64((1 << (ds.k % 64)) - 1)
    light = np.zeros((n, W), dtype=np.uint64)
    ps, ns = np.zeros((n, 3)), np.zeros((n, 3))
    pmn, pmx = np.full((n, 3), np.inf), np.full((n, 3), -np.inf)
    piece_accumulate(inv, pts, nrm, ds._centres, ds._frames, ds.q, ds.hv, ds.hl, 1 if exact else 0, ds.normals,
                     vl, light, ps, ns, pmn, pmx)
    point = ps / np.bincount(inv, minlength=n)[:, None]
    ln = np.linalg.norm(ns, axis=1)
    normal = np.where(ln[:, None] > 0, ns / np.maximum(ln, 1e-300)[:, None], 0.0)
    slab, grow = np.empty(n), np.empty((n, 3))
    patch_slab(inv, pts, nrm, point, normal, step, slab, grow)
    voxel = ukey // nf // 8
    octant = (ukey // nf) % 8
    clo = _octant_lo(origin, d, bijk[voxel], octant)
    return Pieces(voxel=voxel, lo=np.maximum(pmn - grow, clo), hi=np.minimum(pmx + grow, clo + 0.5 * d),
                  light=np.zeros((n, 0), dtype=np.uint64), point=point, normal=normal, slab=slab,
                  face=(ukey % nf).astype(np.int64), vl=vl, octant=octant.astype(np.int64)), light


def _direction_set(q) -> DirectionSet:
    if isinstance(q, bool) or not isinstance(q, (int, np.integer)) or q < 1:
        try:
            DirectionSet(q)
        except ValueError as exc:
            raise AccessModelError(str(exc)) from None
    return direction_set(int(q))


def _check_d(d) -> float:
    try:
        d = float(d)
    except (TypeError, ValueError):
        raise AccessModelError(f"voxel size d must be a positive number of mm, got {d!r}") from None
    if not np.isfinite(d) or d <= 0:
        raise AccessModelError(f"voxel size d must be a positive number of mm, got {d!r}")
    return d


def _check_connected(state, index, fid, vox, pts) -> None:
    from scipy import ndimage

    # edge-connected: 18-neighbourhood
    st = ndimage.generate_binary_structure(3, 2)
    labels, n = ndimage.label(state == BOUNDARY, structure=st)
    if n <= 1:
        return
    lab_of_b = np.empty(int(index.max()) + 1, dtype=np.int64)
    bi = index >= 0
    lab_of_b[index[bi]] = labels[bi]
    lab = lab_of_b[vox]
    sizes = np.bincount(lab, minlength=n + 1)
    main = int(np.argmax(sizes))
    parts = []
    for comp in np.argsort(-sizes):
        if comp == main or comp == 0 or sizes[comp] == 0:
            continue
        faces = np.unique(fid[lab == comp])
        where = pts[lab == comp].mean(axis=0)
        parts.append(f"faces {_ranges(faces)} near ({where[0]:.1f}, {where[1]:.1f}, {where[2]:.1f}) mm")
        if len(parts) == 3:
            break
    raise AccessModelError(
        f"the boundary voxels form {n} pieces that share no edge (the paper needs one edge-connected "
        f"shell): besides the largest, " + "; ".join(parts) + (" ..." if n > 4 else ""))


def _check_orientation(votes, fid, pts, nrm) -> list[int]:
    """Faces to turn (all normals inward); raises where a face points both ways."""
    flipped = []
    bad = []
    for f in range(votes.shape[0]):
        out_, in_ = votes[f, 0], votes[f, 1]
        tot = out_ + in_
        if tot == 0:
            continue
        if in_ <= 0.02 * tot:
            continue
        if out_ <= 0.02 * tot:
            flipped.append(f)
            continue
        sel = (fid == f)
        where = pts[sel].mean(axis=0)
        bad.append(f"face {f} ({out_} samples point out, {in_} in, around "
                   f"({where[0]:.1f}, {where[1]:.1f}, {where[2]:.1f}) mm)")
    if bad:
        raise AccessModelError("no consistent outward side: " + "; ".join(bad[:4])
                               + (f" and {len(bad) - 4} more faces" if len(bad) > 4 else "")
                               + " (a face with two outward sides, or a gap or wall narrower than the voxel:"
                               " try a smaller --voxel)")
    return flipped


def _ranges(ids) -> str:
    ids = sorted(int(i) for i in ids)
    out = []
    start = prev = ids[0]
    for i in ids[1:] + [None]:
        if i is not None and i == prev + 1:
            prev = i
            continue
        out.append(str(start) if start == prev else f"{start}-{prev}")
        if i is not None:
            start = prev = i
    return ",".join(out[:8]) + (",..." if len(out) > 8 else "")


def paint(state: np.ndarray) -> np.ndarray:
    """Paint spreading on a boundary mask or state grid: returns the state (0 exterior,
    1 boundary, 2 interior). Non-boundary voxels 6-connected to the grid's border are exterior.

    Examples
    --------
    >>> b = np.zeros((5, 5, 5), bool); b[1:4, 1:4, 1:4] = True; b[2, 2, 2] = False
    >>> int((paint(b) == 2).sum())
    1
    """
    from ._access_kernels import paint_exterior

    st = np.where(np.asarray(state).astype(bool) & (np.asarray(state) != INTERIOR), BOUNDARY,
                  UNPAINTED).astype(np.uint8)
    if np.asarray(state).dtype == np.uint8:
        st = np.where(np.asarray(state) == BOUNDARY, BOUNDARY, UNPAINTED).astype(np.uint8)
    paint_exterior(st)
    return st


def _opposite(ds: DirectionSet) -> np.ndarray:
    return ds.lookup(-ds.normals).astype(np.int64)


def _hide_masks(normals: np.ndarray, tiny: float = 1e-9) -> np.ndarray:
    """Per direction n, the 27-bit mask (as in ``skin_masks``) of the neighbours a line along n
    can enter when it leaves a voxel: offsets in {0, sign n_c} per axis ({-1, 0, 1} where
    |n_c| < tiny), the voxel itself excluded. A skin cube whose neighbours there are all
    interior hides nothing along n."""
    out = np.zeros(len(normals), dtype=np.int64)
    for i, n in enumerate(np.asarray(normals, dtype=np.float64)):
        sets = [(-1, 0, 1) if abs(c) < tiny else (0, 1 if c > 0 else -1) for c in n]
        m = 0
        for dx in sets[0]:
            for dy in sets[1]:
                for dz in sets[2]:
                    if dx or dy or dz:
                        m |= 1 << ((dx + 1) * 9 + (dy + 1) * 3 + (dz + 1))
        out[i] = m
    return out


def _query_boxes(vm: VoxelMap, pieces: bool = False, fine: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Centres and half extents (mb, 3) of the casting's cylinders: the tight boxes grown to at
    least d' on each axis (a flat box seen at a grazing angle holds no line), within the voxel
    (``pieces``: the pieces' boxes, within their voxels; ``fine``: the half-voxel pieces' of
    ``vm.fine``, within their half-voxel cells)."""
    size = vm.d
    if fine:
        p = vm.fine
        c, h = 0.5 * (p.lo + p.hi), 0.5 * (p.hi - p.lo)
        size = 0.5 * vm.d
        vlo = _octant_lo(vm.origin, vm.d, vm.ijk[p.voxel], p.octant)
    elif pieces:
        p = vm.pieces
        c, h = 0.5 * (p.lo + p.hi), 0.5 * (p.hi - p.lo)
        vlo = vm.origin + vm.d * vm.ijk[p.voxel]
    else:
        c, h = vm.boxes(tight=True)
        vlo = vm.origin + vm.d * vm.ijk
    t = np.maximum(0.5 * vm.sampling_step - h, 0.0)
    lo, hi = np.maximum(c - h - t, vlo), np.minimum(c + h + t, vlo + size)
    return np.ascontiguousarray(0.5 * (lo + hi)), np.ascontiguousarray(0.5 * (hi - lo))


def _skin_boxes(vm: VoxelMap, sijk: np.ndarray, smask: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The skin cubes merged into boxes of cubes with one neighbour mask
    (:func:`~zmap.access._access_kernels.merge_runs`): centres, half extents (n, 3) and masks.
    A box is left out of a direction exactly when each of its cubes would be, and its lines'
    exits are the largest of its cubes', so the casting's bits are those of the cubes."""
    from ._access_kernels import merge_runs

    code = np.zeros(vm.state.shape, dtype=np.int32)  # int32: the grid can be large
    code[tuple(sijk.T)] = smask + 1  # 0: not skin
    rows = np.empty((len(sijk), 7), dtype=np.int64)
    n = merge_runs(code, rows)
    rows = rows[:n]
    lo, hi = rows[:, :3], rows[:, 3:6] + 1
    centre = vm.origin + vm.d * 0.5 * (lo + hi)
    half = 0.5 * vm.d * (hi - lo)
    return np.ascontiguousarray(centre), np.ascontiguousarray(half), np.ascontiguousarray(rows[:, 6] - 1)


def _merged_blockers(vm: VoxelMap, blockers: tuple[np.ndarray, ...]) -> tuple[np.ndarray, ...]:
    """:meth:`VoxelMap.blockers` with the flat boxes of axis-aligned planar faces merged (and
    any further per-blocker arrays in ``blockers`` after the five, a merged box taking its
    first member's).

    A voxel crossed by one face whose patch is a plane square to an axis (slab 0), with a box
    that spans the voxel across that axis, is merged with the voxels of the same face, plane,
    extent along the axis and light set next to it (:func:`~zmap.access._access_kernels.merge_runs`
    on the lattice). Such boxes tile the merged box, and so do their growths by a ray's
    offset, and their slabs are one plane: a line meets the merged box exactly where it meets
    one of them and leaves it at the largest of their exits, so the depth buffers hold the
    same values (their planes and extents along the axis differ in the last bits: the merged
    box takes their union and the lowest slab). A merged box answers for several voxels, so voxels that query and block one
    direction (:func:`_self_blocking`; the casting skips their own box by its voxel number)
    stay apart."""
    from ._access_kernels import merge_runs, run_members

    c, h, bvox, blight, bplane, *extra = blockers
    lo, hi = c - h, c + h
    nrm = bplane[:, 3:6]
    ax = np.argmax(np.abs(nrm), axis=1)
    rows = np.arange(len(c))
    vox = np.clip(bvox, 0, None)
    vlo = vm.origin + vm.d * vm.ijk[vox]
    ok = (np.abs(nrm[rows, ax]) == 1.0) & (bplane[:, 6] <= 1e-9 * vm.d) & (bvox >= 0)
    ok &= vm.surface[vox] >= 0  # one face in the voxel: its box, not a piece
    ok &= ~_self_blocking(vm)[vox]
    for a in range(3):
        tang = ax != a
        ok &= ~tang | ((lo[:, a] <= vlo[:, a]) & (hi[:, a] >= vlo[:, a] + vm.d))
    cand = np.flatnonzero(ok)
    if len(cand) < 2:
        return blockers
    # one group per face, axis, side, plane and extent along the axis, and light set
    offset = (bplane[:, :3] * nrm).sum(axis=1)  # the plane's, in the last bits per voxel

    def nano(x: np.ndarray) -> np.ndarray:  # in nanometres: planes equal but for the last bits
        return np.round(x * 1e9).astype(np.int64)[:, None]

    key = np.concatenate([vm.surface[vox[cand]][:, None].astype(np.int64), ax[cand, None].astype(np.int64),
                          np.sign(nrm[cand, ax[cand]]).astype(np.int64)[:, None], nano(offset[cand]),
                          nano(lo[cand, ax[cand]]), nano(hi[cand, ax[cand]]), blight[cand].view(np.int64)], axis=1)
    group = _row_groups(key)
    code = np.zeros(vm.state.shape, dtype=np.int32)
    code[tuple(vm.ijk[vox[cand]].T)] = group.ravel() + 1
    runs = np.empty((len(cand), 7), dtype=np.int64)
    n = merge_runs(code, runs)
    runs = runs[:n]
    # one member of each run stands for it (the runs' first voxel): its light, plane, axis
    first = np.full(code.shape, -1, dtype=np.int32)
    first[tuple(vm.ijk[vox[cand]].T)] = cand
    rep = first[runs[:, 0], runs[:, 1], runs[:, 2]]
    mlo = vm.origin + vm.d * runs[:, :3]
    mhi = vm.origin + vm.d * (runs[:, 3:6] + 1)
    keep = np.flatnonzero(~ok)
    # per run, the union of its members along the axis and the slab reaching as low as the
    # lowest of theirs (they differ in the last bits)
    plane = bplane[rep].copy()
    mslab = np.empty(n)
    run_members(runs, first, ax.astype(np.int64), lo, hi, offset, np.ascontiguousarray(bplane[:, 6]), mlo, mhi, mslab)
    plane[:, 6] = mslab
    return (np.ascontiguousarray(np.concatenate([c[keep], 0.5 * (mlo + mhi)])),
            np.ascontiguousarray(np.concatenate([h[keep], 0.5 * (mhi - mlo)])),
            np.ascontiguousarray(np.concatenate([bvox[keep], bvox[rep]])),
            np.ascontiguousarray(np.concatenate([blight[keep], blight[rep]])),
            np.ascontiguousarray(np.concatenate([bplane[keep], plane])),
            *(np.ascontiguousarray(np.concatenate([x[keep], x[rep]])) for x in extra))


def _row_groups(key: np.ndarray) -> np.ndarray:
    """Group number per row of ``key`` (int64), equal rows alike: by a 64-bit hash of each row,
    checked against the rows (``np.unique(axis=0)``, several times slower, if any differ)."""
    from ._access_kernels import row_hash

    key = np.ascontiguousarray(key)
    h = np.empty(len(key), dtype=np.uint64)
    row_hash(key, h)
    _, first, group = np.unique(h, return_index=True, return_inverse=True)
    group = group.ravel()
    if (key[first[group]] == key).all():
        return group
    return np.unique(key, axis=0, return_inverse=True)[1].ravel()


def _self_blocking(vm: VoxelMap) -> np.ndarray:
    """Per boundary voxel, whether it has a direction n in V'_l with the direction set's
    opposite of n in L' (a query that is also a blocker of its own direction: the casting then
    skips its own box by its voxel number)."""
    from ._access_kernels import self_blocking

    out = np.zeros(vm.n_boundary, dtype=np.uint8)
    self_blocking(vm.vl, vm.light, _opposite(vm.directions), out)
    return out.astype(bool)


def global_visibility(vm: VoxelMap, *, rays: int = 2, cull: bool = True, pieces: bool = False,
                      refine: bool = False) -> np.ndarray | tuple[np.ndarray, ...]:
    """``V'_g`` of every boundary voxel by cylinder casting (paper 002 §4.5).

    A direction n stays in ``V'_g(v)`` when no line parallel to n through v's surface box
    meets, ahead of v's surface patch, an interior voxel or a boundary voxel w with -n in
    ``L'(w)``. "Ahead" starts where the line enters the box, or later where the patch's slab
    (``vm.slab``) shows that no patch point on the line lies lower: blockers behind the patch
    (the interior cube under a flat face, the box of the voxel across a convex edge) cannot
    stop a ray that leaves the patch, and the paper's cylinder from the whole voxel counted
    them (on featuretype.STEP 388 of its 474 disagreements with the OCC rays were such).
    The lines are those of a plane grid of pitch ``d / rays`` (one depth buffer per
    direction); the blockers are those of :meth:`VoxelMap.blockers` (tight boxes, one per
    face where several meet), v's cylinder comes from its tight box made at least d' thick
    within the voxel (a flat box seen at a grazing angle would hold no line). ``cull``
    (default) leaves out, per direction, the skin cubes whose neighbours on its side are all
    interior (the same bits, less work; ``False`` is for tests). The skin cubes are drawn as
    boxes of cubes that share their neighbour mask (:func:`_skin_boxes`: on featuretype.STEP
    at d = 0.5, 145,222 cubes in 9,996 boxes), and the flat blockers of axis-aligned planar
    faces as runs along their faces (:func:`_merged_blockers`: 152,877 blockers in 56,831),
    again with the same bits.

    ``pieces=True`` also casts each piece of the voxels where several faces meet
    (:class:`Pieces`) as a query of its own, from its own box and slab with its own ``V'_l``:
    the directions free from that face's patch in the voxel, which a point of the face has
    (the voxel's ``V'_l`` is the AND over all its faces: at a convex edge, few directions).
    The voxels' bits are the same either way.

    ``refine=True`` decides finer than a voxel where the voxel-wide cylinder is blocked. Each
    half-voxel piece of ``vm.fine`` (one face's samples in one of the voxel's eight cells of
    edge d / 2) starts with the bits of its voxel, or of its face's piece where several faces
    meet, and is cast again as a query of its own (its own box, slab and ``V'_l``) on depth
    buffers of half the pitch (d / (2 rays), the blockers grown half as much), for only the
    directions of its ``V'_l`` that its voxel's cylinder lost and that some boundary voxel
    within one voxel keeps (near the direction's shadow edge, where a voxel-wide cylinder
    blocks what a thinner one may not; in deep shadow the thinner one is blocked too, and
    leaving it out only keeps a block): the same casting, a thinner cylinder. The fine
    buffers are drawn only over tiles under the pieces cast (the same bits). A half-voxel
    piece keeps the directions either cast finds free. A voxel (a
    piece) then also keeps the directions that all its half-voxel pieces (of its face) keep:
    its patch is their union, and each is cast from its own part of it. Each cast is the
    paper's (lines through cell centres), so the refined map is as conservative as that
    casting is for a cylinder of that size, no more: on 32 random cavities the thinner
    cylinders kept a pair blocked farther than a voxel on 3 where the voxels' did not (rays
    just under the rim; ``_FINE_STRICT`` casts so that they do not, freeing half as much).
    On featuretype.STEP at d = 0.5, q = 4 the refinement took the
    agreement with the OCC thin rays on 300 points (``bench/access.py``, seed 0) from 98.457 %
    to 99.218 % (99.268 % casting every lost direction, for ten times the pairs).

    Returns
    -------
    ndarray of shape (mb, words), uint64; with ``pieces``, also the pieces' (np, words); with
    ``refine`` (and ``pieces``), the voxels', the pieces' and the half-voxel pieces' (nf, words)
    """
    from ._access_kernels import pack_columns

    ds = vm.directions
    cast = _casting(vm, cull=cull)
    qx, qh = _query_boxes(vm)
    mb = vm.n_boundary
    qid = np.arange(mb, dtype=np.int64)
    light, vl, ppt, pnrm, slab = vm.light, vm.vl, vm.point, vm.normal, vm.slabs()
    extra = (pieces or refine) and vm.pieces is not None and vm.pieces.vl is not None
    if extra:
        p = vm.pieces
        px, ph = _query_boxes(vm, pieces=True)
        qx, qh = np.concatenate([qx, px]), np.concatenate([qh, ph])
        qid = np.concatenate([qid, -3 - np.arange(len(p.voxel), dtype=np.int64)])  # skip nothing as itself
        light, vl = np.concatenate([light, p.light]), np.concatenate([vl, p.vl])
        ppt, pnrm, slab = np.concatenate([ppt, p.point]), np.concatenate([pnrm, p.normal]), np.concatenate([slab, p.slab])
    out = _cast(vm, cast, qx, qh, qid, light, vl, ppt, pnrm, slab, vm.d / rays, tile=_TILE)
    bits = np.empty((len(qx), ds.words), dtype=np.uint64)
    pack_columns(out, bits)
    del out
    if refine and vm.fine is not None and vm.fine.octant is not None:
        vb, pb = bits[:mb], (bits[mb:] if extra else np.zeros((0, ds.words), dtype=np.uint64))
        vb, pb, fb = _refine(vm, cast, vb, pb, rays)
        return (vb, pb, fb) if pieces else vb
    if refine and pieces:
        nofine = np.zeros((0, ds.words), dtype=np.uint64)
        return (bits[:mb], bits[mb:], nofine) if extra else (bits, np.zeros((0, ds.words), dtype=np.uint64), nofine)
    if not pieces:
        return bits[:mb]
    if not extra:
        return bits, np.zeros((0, ds.words), dtype=np.uint64)
    return bits[:mb], bits[mb:]


#: tiles of the casting's depth buffers, in cells (:func:`~zmap.access._access_kernels.cast_directions`:
#: blockers behind every query of their tiles are not drawn; 0: all drawn, the same bits), for
#: the voxels' cast and the refinement's. On featuretype.STEP the tiles cost the voxels' cast
#: more than they save (6.5 against 5.3 CPU s), and save the refinement's a third (6.2
#: against 9.2), where few queries ask for each direction.
_TILE, _FINE_TILE = 0, 8
#: 1: the refinement tests every cell under a half-voxel piece's box from the lowest start of a
#: ray of the cell (``strict`` of :func:`~zmap.access._access_kernels.cast_directions`), not
#: only the cells' lines that cross the box from their own starts, as the voxels' cast does
#: (0, the default). On featuretype.STEP (300 points, seed 0) strict frees 0.71 M pairs
#: instead of 1.43 M: agreement 98.867 % instead of 99.218 %. On 32 random cavities it adds
#: no far miss to the voxels' cast, where the default added 1, 2 and 4 pairs on 3 of them
#: (rays passing just under the rim; the voxels' cast itself keeps 1-2 on 11 of the 32).
_FINE_STRICT = 0
#: the refinement's buffers have this many times the voxels' cast's lines per voxel edge
_FINE_RAYS = 2


def _casting(vm: VoxelMap, *, cull: bool = True) -> tuple:
    """What every cast of :func:`global_visibility` shares: the blockers (merged), the skin
    boxes with their masks, the culling masks, and the grid's radius and centre (from the
    voxels' query boxes and the skin cubes)."""
    from ._access_kernels import skin_masks

    ds = vm.directions
    blockers = _merged_blockers(vm, tuple(np.ascontiguousarray(a) for a in vm.blockers()))
    qx, _ = _query_boxes(vm)
    sijk = vm.skin_ijk()
    skin = np.ascontiguousarray(vm.origin + vm.d * (sijk + 0.5))
    smask = np.zeros(len(sijk), dtype=np.int64)
    skin_masks(vm.state, np.ascontiguousarray(sijk, dtype=np.int64), smask)
    allc = np.concatenate([qx, skin]) if len(skin) else qx  # the grid's extent: the cubes'
    skin, shalf, smask = _skin_boxes(vm, sijk, smask)
    lo_, hi_ = allc.min(axis=0), allc.max(axis=0)
    centre = 0.5 * (lo_ + hi_)
    radius = 0.5 * float(np.linalg.norm(hi_ - lo_)) + vm.d
    hide = _hide_masks(ds.normals) if cull else np.full(ds.k, 1 << 27, dtype=np.int64)  # bit 27: never set
    return blockers, skin, shalf, smask, hide, radius, centre


def _cast(vm: VoxelMap, cast: tuple, qx, qh, qid, light, vl, ppt, pnrm, slab, cell: float,
          tile: int = 0, strict: bool = False, lists: bool = False) -> np.ndarray:
    """One run of :func:`~zmap.access._access_kernels.cast_directions` on the queries given:
    ``out`` (k, nq) uint8 (``tile``: draw only the blockers over tiles of that many cells under
    a query that asks, the same bits; ``strict``: every cell under a query's box, from the
    lowest start of a ray of the cell; ``lists``: hand the kernel the queries of each direction,
    worth it where few ask)."""
    from ._access_kernels import bit_lists, cast_directions

    ds = vm.directions
    (bx, bh, bvox, blight, bplane), skin, shalf, smask, hide, radius, centre = cast
    out = np.zeros((ds.k, len(qx)), dtype=np.uint8)
    vl = np.ascontiguousarray(vl)
    qptr, qidx = np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    if lists:
        qptr = np.zeros(ds.k + 1, dtype=np.int64)
        qidx = np.empty(int(count(vl).sum()), dtype=np.int64)
        bit_lists(vl, ds.k, qptr, qidx)
    cast_directions(ds.normals, _opposite(ds), bx, bh, bvox, blight, bplane, np.ascontiguousarray(qx),
                    np.ascontiguousarray(qh), np.ascontiguousarray(qid), skin, shalf, hide, smask,
                    np.ascontiguousarray(light), np.ascontiguousarray(vl), np.ascontiguousarray(ppt),
                    np.ascontiguousarray(pnrm), np.ascontiguousarray(slab), vm.d, cell, radius, centre, int(tile), int(strict), qptr, qidx, out)
    return out


def _piece_index(vm: VoxelMap, voxel: np.ndarray, face: np.ndarray) -> np.ndarray:
    """Index into ``vm.pieces`` of each (voxel, face), -1 where there is none."""
    p = vm.pieces
    out = np.full(len(voxel), -1, dtype=np.int64)
    if p is None or p.face is None or not len(p.voxel) or not len(voxel):
        return out
    nf = int(max(p.face.max(), np.max(face))) + 1
    keys = p.voxel.astype(np.int64) * nf + p.face
    order = np.argsort(keys, kind="stable")
    want = np.asarray(voxel, dtype=np.int64) * nf + np.asarray(face, dtype=np.int64)
    at = np.clip(np.searchsorted(keys[order], want), 0, len(keys) - 1)
    hit = keys[order][at] == want
    out[hit] = order[at[hit]]
    return out


#: the last refinement's figures (:func:`global_visibility` with ``refine=True``), for benches:
#: half-voxel pieces, those cast again, (piece, direction) pairs cast again, pairs it freed,
#: voxel and piece pairs it freed
_LAST_REFINE_STATS: dict = {}


#: the refinement casts a half-voxel piece's direction only where a boundary voxel within this
#: many voxels (along each axis) keeps it; -1: everywhere (tests)
_REFINE_NEAR = 1


def _refine(vm: VoxelMap, cast: tuple, vb: np.ndarray, pb: np.ndarray, rays: int, near: int | None = None,
            tile: int | None = None):
    """The refinement of :func:`global_visibility` (``refine=True``): the half-voxel pieces
    cast at half the pitch for the directions of their V'_l their voxel (piece) lost and some
    boundary voxel within ``near`` voxels keeps (itself or one of its pieces); then the voxels
    and pieces keep what all their half-voxel pieces keep."""
    from ._access_kernels import dilate_bits, pack_columns

    ds = vm.directions
    f = vm.fine
    nfine = len(f.voxel)
    # each half-voxel piece starts from its voxel's bits, or its face's piece's
    parent = vb[f.voxel].copy()
    pi = _piece_index(vm, f.voxel, f.face) if len(pb) else np.full(nfine, -1, dtype=np.int64)
    has = pi >= 0
    parent[has] = pb[pi[has]]
    need = f.vl & ~parent
    near = _REFINE_NEAR if near is None else near
    if near >= 0:
        # only near a direction's shadow edge: some voxel within `near` keeps it (in deep
        # shadow the thinner cylinder is blocked too; leaving it out only keeps a block)
        anyf = vb.copy()
        if len(pb):
            np.bitwise_or.at(anyf, vm.pieces.voxel, pb)
        dil = np.empty_like(anyf)
        dilate_bits(vm.index, np.ascontiguousarray(vm.ijk, dtype=np.int64), anyf, int(near), dil)
        need &= dil[f.voxel]
    todo = np.flatnonzero(need.any(axis=1))
    fb = parent
    if len(todo):
        qx, qh = _query_boxes(vm, fine=True)
        qid = -3 - np.arange(len(todo), dtype=np.int64)
        out = _cast(vm, cast, qx[todo], qh[todo], qid, np.zeros((len(todo), ds.words), dtype=np.uint64), need[todo],
                    f.point[todo], f.normal[todo], f.slab[todo], vm.d / (_FINE_RAYS * rays),
                    tile=_FINE_TILE if tile is None else tile, strict=_FINE_STRICT, lists=True)
        got = np.empty((len(todo), ds.words), dtype=np.uint64)
        pack_columns(out, got)
        fb[todo] |= got
    else:
        got = np.zeros((0, ds.words), dtype=np.uint64)
    vb0, pb0 = count(vb).sum(), count(pb).sum() if len(pb) else 0
    # a voxel keeps what all its half-voxel pieces keep (they are sorted by voxel)
    start = np.flatnonzero(np.r_[True, f.voxel[1:] != f.voxel[:-1]])
    vb = vb.copy()
    vb[f.voxel[start]] |= np.bitwise_and.reduceat(fb, start, axis=0)
    if len(pb):
        # a piece keeps what all the half-voxel pieces of its face in its voxel keep
        sel = np.flatnonzero(has)
        order = sel[np.argsort(pi[sel], kind="stable")]
        ps = pi[order]
        st = np.flatnonzero(np.r_[True, ps[1:] != ps[:-1]])
        pb = pb.copy()
        pb[ps[st]] |= np.bitwise_and.reduceat(fb[order], st, axis=0)
    _LAST_REFINE_STATS.clear()
    _LAST_REFINE_STATS.update(pieces=int(nfine), cast=int(len(todo)), pairs=int(count(need).sum()),
                              freed=int(count(got).sum()), voxel_pairs_freed=int(count(vb).sum() - vb0),
                              piece_pairs_freed=int((count(pb).sum() if len(pb) else 0) - pb0))
    return vb, pb, fb


def _disc_rows(rad: float, *, outer: bool) -> np.ndarray:
    """Half-widths per row offset |dp| = 0, 1, ... (-1: none) of the cell offsets that a disc
    of radius ``rad`` cells, centred anywhere in cell (0, 0), can meet (``outer``: the cells'
    nearest points closer than rad) or always meets (not ``outer``: their farthest points
    closer than rad). The margins keep the first a superset and the second a subset under
    rounding."""
    rad = float(rad)
    if rad <= 0:
        return np.zeros(1, dtype=np.int64)
    n = int(np.ceil(rad)) + 2
    o = np.arange(n + 1)
    if outer:
        g = np.maximum(o - 1, 0).astype(float)
        inside = g[:, None] ** 2 + g[None, :] ** 2 < rad * rad * (1 + 1e-6)
    else:
        inside = o[:, None] ** 2 + o[None, :] ** 2 < rad * rad * (1 - 1e-6)
    inside[0, 0] = True
    w = np.array([np.flatnonzero(inside[p]).max() if inside[p].any() else -1 for p in range(n + 1)])
    last = int(np.flatnonzero(w >= 0).max())
    return w[:last + 1].astype(np.int64)


def _covered_rows(rad: float) -> np.ndarray:
    """Half-widths per row offset |dp| = 0, 1, ... (-1: none) of the cell offsets that a disc of
    radius ``rad`` cells, centred anywhere in cell (0, 0), always covers whole: the farthest
    point of cell (p, q) lies (|p| + 1, |q| + 1) cells away (a margin keeps it a subset)."""
    rad = float(rad)
    n = max(int(np.ceil(rad)), 1)
    o = np.arange(n + 1, dtype=float)
    inside = (o[:, None] + 1) ** 2 + (o[None, :] + 1) ** 2 < rad * rad * (1 - 1e-9)
    w = np.array([np.flatnonzero(row).max() if row.any() else -1 for row in inside], dtype=np.int64)
    keep = np.flatnonzero(w >= 0)
    return w[:keep.max() + 1] if len(keep) else w[:1]


#: pairs the last :func:`accessibility` call decided by the dilated buffers as clear, as
#: blocked, and by scanning the disc (shank and holder tests together); for benches.
_LAST_TOOL_STATS = [0, 0, 0]


def _curved(vm: VoxelMap, a: float) -> np.ndarray:
    """The voxels (mb,) bool whose largest concave curvature exceeds 1/a: no ball of radius a
    touches them without cutting their neighbourhood (condition 2)."""
    return vm.curvature > (1.0 / a) * (1 + 1e-9)


def _ball_inputs(vm: VoxelMap, a: float) -> tuple[float, np.ndarray, np.ndarray]:
    """What the ball's conditions (:func:`accessibility`) take besides the maps, for a ball of
    radius ``a``: half a voxel diagonal ``hd``; ``bad`` (mb,) uint8, bit 1 for the voxels that
    get no direction themselves (a concave curvature above 1/a, or any crease: its ball sits at
    its faces' mean point and normal, the ball of none of its points), bit 2 for those that bar
    the ball as its neighbours (the curvature, or a concave crease); ``cap`` (k, words), per
    tessel of x_w - c the directions for which a shell voxel lies beyond the eraser's equator
    (n . v_j > hd / (a - hd) for the tessel's three vertices: conservative)."""
    from .directions import from_bool

    ds = vm.directions
    hd = float(np.sqrt(3.0) * 0.5 * vm.d)
    thr = hd / (a - hd) if a > hd else np.inf
    cap = from_bool((np.einsum("tjx,nx->tjn", ds.vertices, ds.normals) > thr).all(axis=1))
    curved = _curved(vm, a)
    bad = (curved | vm.crease).astype(np.uint8) | (2 * (curved | _concave_creases(vm))).astype(np.uint8)
    return hd, bad, cap


def _concave_creases(vm: VoxelMap) -> np.ndarray:
    """The crease voxels (mb,) bool that bar a ball as its neighbours (condition 3): all but
    those whose faces all meet convexly, each piece's mean point below every other piece's
    plane by more than 1e-3 d unless the two normals are within 10 degrees (a flat join): the
    part's outer edges and corners, whose material lies under each face's plane, which a ball
    touching a face from outside stays above."""
    out = vm.crease.astype(bool).copy()
    p = vm.pieces
    if p is None or not len(p.voxel) or not out.any():
        return out
    start = np.flatnonzero(np.r_[True, p.voxel[1:] != p.voxel[:-1]])  # pieces come sorted by voxel
    size = np.diff(np.r_[start, len(p.voxel)])
    # every ordered pair (i, j) of pieces of a voxel, i != j
    owner = np.repeat(np.arange(len(start)), size * size)
    k = np.arange(len(owner)) - np.repeat(np.cumsum(size * size) - size * size, size * size)
    i = start[owner] + k // size[owner]
    j = start[owner] + k % size[owner]
    pair = i != j
    i, j, owner = i[pair], j[pair], owner[pair]
    below = ((p.point[j] - p.point[i]) * p.normal[i]).sum(axis=1) < -1e-3 * vm.d
    below |= (p.normal[i] * p.normal[j]).sum(axis=1) > np.cos(np.radians(10.0))
    convex = np.ones(len(start), dtype=bool)
    convex[owner[~below]] = False
    vox = p.voxel[start]
    out[vox[convex & (size > 1)]] = False
    return out


def accessibility(vm: VoxelMap, vg: np.ndarray, tool: Tool, *, cell: float | None = None,
                  cell_holder: float | None = None, method: str = "capsule",
                  pieces: bool = False,
                  samples: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
                  ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Ball-end accessibility map ``A'`` (paper 002 §4.6) with shank and holder.

    ``method="paper"``: n is in ``A'(v)`` when n is in ``V'_g(v)`` and

    1. n is in ``V'_g(w)`` for every boundary voxel w of ``E_n(v)``: those whose centres lie
       within half a voxel diagonal of the eraser's surface, on its side facing -n (the ball
       of radius a centred at v's mean point plus a times its mean normal);
    2. no voxel of ``E_n(v)`` has a concave curvature above 1/a;
    3. no voxel of ``E_n(v)`` is a concave crease (several faces meeting at an angle, not all
       convexly: :func:`_concave_creases`), and v is no crease at all (its ball, at its faces'
       mean point and normal, is the ball of none of its points);

    and the shank and the holder clear (below).

    ``method="capsule"`` (the default): the ball withdrawn along n sweeps the capsule of
    radius a around the ray from its centre c, that is the ball itself and the half cylinder
    above c's plane across n, which is the shank's test when the shank is as wide as the ball
    (it is: :class:`Tool`). So n is in ``A'(v)`` when n is in ``V'_l(v)``, v is neither a
    crease nor curved concavely above 1/a (condition 2 and 3 for v itself), the ball holds no
    boundary or interior voxel centre closer than a - half a voxel diagonal to c, and the
    shank and the holder clear. The thin ray of ``V'_g`` from v's point lies inside the
    capsule (for n . normal > 0), so ``V'_g`` is not needed (``vg`` is not read; the cast's
    voxel-wide cylinders lose grazing directions that the tool clears, so ``A'`` may hold a
    direction that ``V'_g`` lost), and the paper's conditions 1-3 over ``E_n(v)`` stand in for
    the swept ball with the neighbours' voxels, which the shank's test replaces by the
    blockers themselves.

    With ``pieces=True`` (capsule only) each piece of ``vm.pieces`` (a face in a voxel where
    several meet) gets its own ``A'`` too, from its face's mean point, normal and ``V'_l``, and
    a crease voxel, which has none of its own, the directions all its pieces share: a point on
    either side of an edge is then answered for its own face, as the thin rays are.

    With ``samples`` ``(points, normals, face)`` (the part's surface samples, those the map
    was built from; capsule only) the balls and cylinders are tested on the samples instead
    of the voxels: each ball touches the sample of its face nearest its voxel's (or piece's)
    mean point, with that sample's normal (a mean point of a curved face lies off the
    surface); it fits when no sample lies closer than a - 1e-3 mm to its centre; the
    directions asked are that normal's open hemisphere and a few degrees below it
    (``_GRAZE``), not ``V'_l``, and the shank and the holder are tested as by
    :func:`tool_clearance` with ``samples``. (The voxel-sized slack of the blockers' boxes
    was most of what the map refused and OCC's tool allowed.)

    Without samples, no blocker may reach above the ball's centre within the shank's radius, nor
    above the stick-out within the holder's radius (both tested upward without end; cells of
    the depth buffers: ``cell``, d by default, and ``cell_holder``, the larger of d and a fifth
    of the holder's radius; see :func:`tool_clearance`), and a voxel where the ball itself
    would hold a boundary or interior voxel centre closer than a - half a diagonal to its
    centre has no direction.

    Returns
    -------
    ndarray of shape (mb, words), uint64; with ``pieces``, also the pieces' (np, words)
    """
    from ._access_kernels import ball_conditions, ball_fits

    if method not in ("capsule", "paper"):
        raise ValueError(f"method must be 'capsule' or 'paper', got {method!r}")
    a = tool.radius
    bbox = vm.centres.max(axis=0) - vm.centres.min(axis=0)
    if 2 * a > float(bbox.max()) + vm.d:
        raise AccessModelError(f"tool diameter {tool.diameter:g} mm is larger than the part "
                               f"({bbox[0]:.1f} x {bbox[1]:.1f} x {bbox[2]:.1f} mm)")
    ds = vm.directions
    hd, bad, cap = _ball_inputs(vm, a)
    centre = np.ascontiguousarray(vm.point + a * vm.normal)
    if method == "paper":
        if pieces or samples is not None:
            raise ValueError("pieces and samples are answered by method='capsule' only")
        local = np.empty_like(vg)
        ball_conditions(np.ascontiguousarray(vg), np.ascontiguousarray(vm.centres), centre, vm.origin, vm.d,
                        vm.index, vm.state, a - hd, a + hd, bad, cap, ds._centres, ds._frames, ds.q, local)
        return tool_clearance(vm, np.ascontiguousarray(local), tool, cell=cell, cell_holder=cell_holder)
    if samples is not None:
        return _sampled_access(vm, tool, bad, pieces, samples, cell)
    fits = np.empty(vm.n_boundary, dtype=np.bool_)
    ball_fits(centre, vm.origin, vm.d, vm.state, a - hd, fits)
    # not ANDed with V'_g: the capsule holds the thin ray, and the cast's voxel-wide cylinders
    # lose grazing directions at convex edges that the tool clears (featuretype: 0.5 % of pairs)
    local = np.where((fits & (bad & 1 == 0))[:, None], vm.vl, np.uint64(0))
    p = vm.pieces
    if not _has_pieces(vm, pieces):
        return _split_pieces(vm, tool_clearance(vm, np.ascontiguousarray(local), tool, cell=cell,
                                                cell_holder=cell_holder), pieces)
    # the pieces ride along as more queries of the same buffers
    pcentre = np.ascontiguousarray(p.point + a * p.normal)
    pfits = np.empty(len(p.voxel), dtype=np.bool_)
    ball_fits(pcentre, vm.origin, vm.d, vm.state, a - hd, pfits)
    plocal = np.where((pfits & ~_curved(vm, a)[p.voxel])[:, None], p.vl, np.uint64(0))
    both = tool_clearance(vm, np.ascontiguousarray(np.concatenate([local, plocal])), tool, cell=cell,
                          cell_holder=cell_holder,
                          queries=(np.concatenate([vm.point, p.point]), np.concatenate([vm.normal, p.normal]),
                                   np.concatenate([vm.surface.astype(np.int64), p.face])))
    return _split_pieces(vm, both, pieces)


def _snap(tree, spts: np.ndarray, snrm: np.ndarray, sface: np.ndarray, point: np.ndarray,
          face: np.ndarray, k: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """The sample nearest each ``point`` among its ``k`` nearest that lie on ``face`` (any face
    where ``face`` is -1; the point itself, with a zero normal, where none of them does):
    ``(points, normals)``."""
    _, near = tree.query(point, k=min(k, len(spts)), workers=-1)
    near = np.asarray(near).reshape(len(point), -1)
    ok = (sface[near] == face[:, None]) | (face[:, None] < 0)
    first = np.argmax(ok, axis=1)
    pick = near[np.arange(len(point)), first]
    found = ok.any(axis=1)
    return (np.where(found[:, None], spts[pick], point),
            np.where(found[:, None], snrm[pick], 0.0))


#: how far below its tangent plane (as n . normal > -_GRAZE, about 3 degrees) a direction is
#: still asked of the samples: OCC's tool clears such a tilt where the face ends within the
#: reference's 1e-3 mm of intrusion, and the samples answer it alike
_GRAZE = 0.05


def _hemisphere_bits(vm: VoxelMap, normal: np.ndarray) -> np.ndarray:
    """The directions with n . normal > -``_GRAZE``, per row of ``normal`` (m, words)."""
    from ._direction_kernels import above_bits

    ds = vm.directions
    normal = np.ascontiguousarray(normal, dtype=np.float64)
    out = np.empty((len(normal), ds.words), dtype=np.uint64)
    above_bits(np.ascontiguousarray(ds.normals), normal, -_GRAZE, out)
    return out


def _sampled_access(vm: VoxelMap, tool: Tool, bad: np.ndarray, pieces: bool,
                    samples: tuple[np.ndarray, np.ndarray, np.ndarray],
                    cell: float | None) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """:func:`accessibility` by the capsule on the surface samples (its ``samples``)."""
    from scipy.spatial import cKDTree

    spts = np.ascontiguousarray(samples[0], dtype=np.float64)
    snrm = np.asarray(samples[1], dtype=np.float64)
    sface = np.asarray(samples[2], dtype=np.int64)
    if spts.ndim != 2 or spts.shape[1] != 3 or not len(spts) or snrm.shape != spts.shape \
            or sface.shape != (len(spts),):
        raise AccessModelError(f"samples must be points (n, 3), normals (n, 3) and face ids (n,) with n > 0, "
                               f"got shapes {spts.shape}, {snrm.shape} and {sface.shape}")
    a = tool.radius
    tree = cKDTree(spts)
    curved = _curved(vm, a)
    qpoint, qnormal = _snap(tree, spts, snrm, sface, vm.point, vm.surface.astype(np.int64))
    keep = (bad & 1 == 0) & (np.abs(qnormal).sum(axis=1) > 0)
    local = [np.where(keep[:, None], _hemisphere_bits(vm, qnormal), np.uint64(0))]
    qp, qn = [qpoint], [qnormal]
    p = vm.pieces
    if _has_pieces(vm, pieces):
        pp, pn = _snap(tree, spts, snrm, sface, p.point, p.face)
        pkeep = ~curved[p.voxel] & (np.abs(pn).sum(axis=1) > 0)
        local.append(np.where(pkeep[:, None], _hemisphere_bits(vm, pn), np.uint64(0)))
        qp.append(pp)
        qn.append(pn)
    qp, qn, local = np.concatenate(qp), np.concatenate(qn), np.concatenate(local)
    # the ball fits: no sample closer than a (less OCC's 1e-3 mm) to its centre
    dist, _ = tree.query(qp + a * qn, workers=-1)
    local[dist < a - 1e-3] = 0
    both = tool_clearance(vm, np.ascontiguousarray(local), tool, cell=cell,
                          queries=(qp, qn, np.full(len(qp), -1)), samples=spts)
    return _split_pieces(vm, both, pieces)


def _has_pieces(vm: VoxelMap, pieces: bool) -> bool:
    """Whether :func:`accessibility` answers ``vm.pieces`` too (asked, and there are some)."""
    p = vm.pieces
    return bool(pieces and p is not None and len(p.voxel) and p.vl is not None)


def _split_pieces(vm: VoxelMap, both: np.ndarray, pieces: bool) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """:func:`accessibility`'s return from the rows of the voxels' queries and, after them, the
    pieces' (where :func:`_has_pieces`): with ``pieces``, ``(voxels', pieces')``, a crease voxel
    taking the directions all its pieces keep (pieces come sorted by voxel)."""
    amap = both[:vm.n_boundary].copy()
    if not pieces:
        return amap
    p = vm.pieces
    if not _has_pieces(vm, pieces):
        return amap, np.zeros((0 if p is None else len(p.voxel), vm.directions.words), dtype=np.uint64)
    pmap = both[vm.n_boundary:].copy()
    start = np.flatnonzero(np.r_[True, p.voxel[1:] != p.voxel[:-1]])
    shared = np.bitwise_and.reduceat(pmap, start, axis=0)
    vox = p.voxel[start]
    crease = vm.crease[vox].astype(bool)
    amap[vox[crease]] = shared[crease]
    return amap, pmap


def _blocker_faces(vm: VoxelMap) -> np.ndarray:
    """The face of each of :meth:`VoxelMap.blockers` (nb,) int64 (-1: several)."""
    one = np.flatnonzero(vm.surface >= 0) if vm.pieces is not None else np.arange(vm.n_boundary)
    face = vm.surface[one].astype(np.int64)
    if vm.pieces is None:
        return face
    pf = vm.pieces.face if vm.pieces.face is not None else np.full(len(vm.pieces.voxel), -1)
    return np.concatenate([face, np.asarray(pf, dtype=np.int64)])


def _plane_faces(vm: VoxelMap, face: np.ndarray, plane: np.ndarray) -> np.ndarray:
    """Per face id, whether the face is a plane: every voxel that it alone crosses and every
    piece of it has one unit normal (within 1e-9) and a slab of at most 1e-9 d (a connected
    face with one normal is flat). ``face`` and ``plane``: those of :meth:`VoxelMap.blockers`
    (:func:`_blocker_faces` and its fifth array)."""
    normal, slab = plane[:, 3:6], plane[:, 6]
    nf = int(max(face.max(initial=-1), vm.surface.max(initial=-1))) + 1
    if nf == 0:
        return np.zeros(0, dtype=bool)
    ok = face >= 0
    first = np.full(nf, -1, dtype=np.int64)
    idx = np.flatnonzero(ok)
    first[face[idx[::-1]]] = idx[::-1]  # the first blocker of each face
    flat = np.ones(nf, dtype=bool)
    dev = np.abs(normal[idx] - normal[first[face[idx]]]).max(axis=1)
    bad = (dev > 1e-9) | ~(slab[idx] <= 1e-9 * vm.d) | (np.abs(normal[idx]).sum(axis=1) == 0)
    flat[face[idx[bad]]] = False
    flat[first < 0] = False
    return flat


def _plane_queries(vm: VoxelMap, plane: np.ndarray) -> np.ndarray:
    """Per boundary voxel (mb,) int64, the plane face that alone crosses it (-1: none), by the
    faces' flags ``plane`` of :func:`_plane_faces`."""
    surf = vm.surface.astype(np.int64)
    out = np.full(len(surf), -1, dtype=np.int64)
    one = np.flatnonzero(surf >= 0)
    out[one] = np.where(plane[surf[one]], surf[one], -1)
    return out


def tool_clearance(vm: VoxelMap, local: np.ndarray, tool: Tool, *, cell: float | None = None,
                   cell_holder: float | None = None, skin: bool = False,
                   queries: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
                   samples: np.ndarray | None = None) -> np.ndarray:
    """The directions of ``local`` (mb, words) along which the shank and the holder clear the
    part: no blocker of the casting (:meth:`VoxelMap.blockers`, merged) leaves a line of a
    buffer cell meeting the shank's disc above the ball's centre, nor one meeting the holder's
    disc above the stick-out (buffers of pitch ``cell`` and ``cell_holder``, as in
    :func:`accessibility`, which calls it on the ball's local map). A blocker's exit on the
    lines of a cell: its box grown by the lines' offset from the cell's centre line, cut at its
    patch's slab (every patch point lies within ``slab`` of its mean plane).

    A ball on a plane face (:func:`_plane_faces`; the voxel crossed by that face alone) leaves
    the face out of its shank's test: at a tilt t below 90 degrees the shank's points lie
    ``a (1 - sin t)`` or more outside the plane. For the holder, which can dip below the plane,
    the face counts only as high as its plane rises over each cell's part within the disc.

    The interior skin cubes need not be drawn (``skin=False``, the default): both cylinders
    reach upward without end, so a point of material inside one has above it, on the same
    line along n, the point where that line leaves the part, a surface point inside the
    cylinder and higher, on a blocker whose exit on that line the cell holds. (Not on the ball's
    plane face: the shank stays outside that plane.) ``skin=True`` draws the cubes too (a
    subset of the bits).

    ``queries``: ``(point, normal, face)`` (m, 3), (m, 3), (m,) of other balls than the
    boundary voxels' (``local`` is then (m, words)): surface points with their unit normals
    and face ids (-1: none), e.g. the pieces of :func:`accessibility`.

    ``samples`` (ns, 3): the part's surface samples. The cylinders are then tested against
    the samples themselves (:mod:`zmap.access._sample_kernels`): a sample closer than the
    radius less 1e-3 mm to the axis and above the start blocks (OCC's reference allows the
    same 1e-3 mm), with no voxel-sized slack and no plane-face rule (a ball's own plane stays
    outside its shank exactly); ``cell`` is then the pitch of the samples' cells for both
    cylinders (``cell_holder`` is not read).
    """
    from ._access_kernels import pack_columns, tool_kernel

    ds = vm.directions
    a = tool.radius
    qpoint, qnormal = (vm.point, vm.normal) if queries is None else (queries[0], queries[1])
    qpoint = np.ascontiguousarray(qpoint, dtype=np.float64)
    qnormal = np.ascontiguousarray(qnormal, dtype=np.float64)
    centre = np.ascontiguousarray(qpoint + a * qnormal)
    mb = len(qpoint)
    if samples is not None:
        return _sample_clearance(vm, local, tool, centre, np.ascontiguousarray(samples, dtype=np.float64),
                                 float(cell or vm.d))
    sk = vm.skin()
    blockers = tuple(np.ascontiguousarray(x) for x in vm.blockers()) + (_blocker_faces(vm),)
    plane = _plane_faces(vm, blockers[5], blockers[4])
    bc, bh, _, _, bplane, bface = _merged_blockers(vm, blockers)
    # the buffers' grid is laid on the boxes and skin centres either way
    lo_ = np.minimum(bc.min(axis=0), sk.min(axis=0)) if len(sk) else bc.min(axis=0)
    hi_ = np.maximum(bc.max(axis=0), sk.max(axis=0)) if len(sk) else bc.max(axis=0)
    if not skin:
        sk = sk[:0]
    occ = np.ascontiguousarray(np.concatenate([bc, sk]))
    ohalf = np.ascontiguousarray(np.concatenate([bh, np.full((len(sk), 3), 0.5 * vm.d)]))
    splane = np.zeros((len(sk), 7))
    splane[:, 6] = np.inf
    oplane = np.ascontiguousarray(np.concatenate([bplane, splane]))
    oface = np.ascontiguousarray(np.concatenate([bface, np.full(len(sk), -2)]), dtype=np.int64)
    # a ball on a plane face, its shank tilted less than 90 degrees off the normal, stays on the
    # plane's outer side: the shank's test skips that face's blockers
    if queries is None:
        qface = _plane_queries(vm, plane)
    else:
        f = np.asarray(queries[2], dtype=np.int64)
        on_plane = np.zeros(len(f), dtype=bool)
        ok = (f >= 0) & (f < len(plane))
        on_plane[ok] = plane[f[ok]]
        qface = np.where(on_plane, f, -1)
    qface = np.ascontiguousarray(qface, dtype=np.int64)
    mid = 0.5 * (lo_ + hi_)
    radius = 0.5 * float(np.linalg.norm(hi_ - lo_)) + vm.d + a
    out = np.zeros((ds.k, mb), dtype=np.uint8)
    holder_r = tool.holder_diameter / 2.0
    stats = np.zeros((ds.k, 3), dtype=np.int64)
    cell = float(cell or vm.d)
    cell_holder = float(cell_holder or max(vm.d, holder_r / 5))
    # the holder's buffer from the shank's by block maxima where its cell is a power of two
    # times the shank's (the default 20 mm holder at d = 0.5: 4), else drawn box by box
    ratio = cell_holder / cell
    hm = int(round(ratio))
    hm = hm if hm >= 1 and ratio == hm and hm & (hm - 1) == 0 else 0
    tool_kernel(ds.normals, local, centre, qpoint, qnormal, occ, ohalf, oplane, oface, qface, vm.d, a, cell,
                cell_holder, hm, tool.stickout - a, holder_r,
                mid, radius, _disc_rows(a / cell, outer=True), _disc_rows(a / cell, outer=False),
                _disc_rows(holder_r / cell_holder, outer=True), _disc_rows(holder_r / cell_holder, outer=False),
                out, stats)
    _LAST_TOOL_STATS[:] = [int(x) for x in stats.sum(axis=0)]
    bits = np.empty((mb, ds.words), dtype=np.uint64)
    pack_columns(out, bits)
    return bits


def _direction_pairs(ds: DirectionSet) -> tuple[np.ndarray, np.ndarray]:
    """The directions as pairs ``(first, second)``, each with its opposite (-1: none), every
    direction once: the sample kernel sorts the samples once per pair (a direction and its
    opposite share the plane across them)."""
    n = ds.normals
    opp = _opposite(ds)
    idx = np.arange(len(n))
    if not ((np.abs(n[opp] + n).max(axis=1) < 1e-9) & (opp[opp] == idx) & (opp != idx)).all():
        return idx.astype(np.int64), np.full(len(n), -1, dtype=np.int64)
    first = np.flatnonzero(idx < opp).astype(np.int64)
    return first, opp[first]


def _sample_clearance(vm: VoxelMap, local: np.ndarray, tool: Tool, centre: np.ndarray, samples: np.ndarray,
                      cell: float) -> np.ndarray:
    """:func:`tool_clearance` on the surface samples (its ``samples``): (mb, words) uint64."""
    import numba

    from ._access_kernels import pack_columns
    from ._sample_kernels import sample_tool_kernel

    ds = vm.directions
    tol = 1e-3
    r_shank = tool.radius - tol
    r_holder = tool.holder_diameter / 2.0 - tol if tool.holder_diameter > 0 else 0.0
    out = np.zeros((ds.k, len(centre)), dtype=np.uint8)
    stats = np.zeros((ds.k, 3), dtype=np.int64)
    sample_tool_kernel(ds.normals, np.ascontiguousarray(local), centre, samples, r_shank,
                       tool.stickout - tool.radius, r_holder, cell, _disc_rows(r_shank / cell, outer=True),
                       _covered_rows(r_shank / cell), _disc_rows(max(r_holder, 0.0) / cell, outer=True),
                       _covered_rows(max(r_holder, 0.0) / cell), out, stats, numba.get_num_threads(),
                       *_direction_pairs(ds))
    _LAST_TOOL_STATS[:] = [int(x) for x in stats.sum(axis=0)]
    bits = np.empty((len(centre), ds.words), dtype=np.uint64)
    pack_columns(out, bits)
    return bits


def three_axis(vm: VoxelMap, amap: np.ndarray, *, axis="+z") -> dict:
    """The 3-axis verdict: area reachable along ``axis`` and the rest.

    Returns
    -------
    dict
        ``axis_index``, ``reachable`` (bool (mb,)), ``area_total``, ``area_reachable``,
        ``area_other`` (accessible, but not along the axis), ``area_inaccessible`` (mm^2),
        ``share`` (reachable / total).
    """
    ds = vm.directions
    i = ds.index(axis)
    bits = np.asarray(amap)
    reach = ((bits[:, i >> 6] >> np.uint64(i & 63)) & np.uint64(1)).astype(bool)
    anyd = count(bits) > 0
    total = float(vm.area.sum())
    return {"axis_index": i, "reachable": reach, "area_total": total,
            "area_reachable": float(vm.area[reach].sum()),
            "area_other": float(vm.area[anyd & ~reach].sum()),
            "area_inaccessible": float(vm.area[~anyd].sum()),
            "share": float(vm.area[reach].sum() / total) if total > 0 else float("nan")}


def set_cover(vm: VoxelMap, amap: np.ndarray, *, cone: float | None = None, axis="+z",
              max_setups: int = 64) -> list[dict]:
    """Fewest directions that together reach every accessible voxel (greedy set cover by area).

    Parameters
    ----------
    cone : float, optional
        Only directions within this angle (radians) of ``axis`` (a tilt cone, as 3+2 heads
        allow); voxels reachable only outside it stay uncovered.

    Returns
    -------
    list of dict
        One per set-up in the order chosen: ``direction`` index, ``vector``, ``area`` newly
        covered (mm^2), ``voxels`` (their numbers).
    """
    ds = vm.directions
    cand = np.ones(ds.k, bool) if cone is None else ds.within(
        np.asarray(ds.normals[ds.index(axis)] if isinstance(axis, str) else axis), float(cone))
    from ._access_kernels import greedy_cover

    chosen = np.zeros(max_setups, dtype=np.int64)
    gains = np.zeros(max_setups)
    n = greedy_cover(np.ascontiguousarray(amap, dtype=np.uint64), np.ascontiguousarray(vm.area, dtype=np.float64),
                     cand.astype(np.uint8), int(max_setups), chosen, gains)
    setups = []
    left = count(np.asarray(amap) & from_bool(cand)[0]) > 0
    for s_ in range(n):
        j = int(chosen[s_])
        got = left & ((np.asarray(amap)[:, j >> 6] >> np.uint64(j & 63)) & np.uint64(1)).astype(bool)
        setups.append({"direction": j, "vector": ds.normals[j].tolist(), "area": float(gains[s_]),
                       "voxels": np.flatnonzero(got)})
        left &= ~got
    return setups


def node_directions(vm: VoxelMap, amap: np.ndarray, x, y) -> tuple[np.ndarray, np.ndarray]:
    """Per z-map node (x, y): the top-most boundary voxel in its column and its directions.

    Returns
    -------
    voxel : ndarray of shape broadcast(x, y).shape, int64
        Boundary voxel number, -1 where the column holds none.
    n : ndarray of the same shape, int64
        Number of accessible directions there (0 where none or no voxel).
    """
    x, y = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
    i = np.floor((x - vm.origin[0]) / vm.d).astype(np.int64)
    j = np.floor((y - vm.origin[1]) / vm.d).astype(np.int64)
    nx, ny, nz = vm.state.shape
    ok = (i >= 0) & (i < nx) & (j >= 0) & (j < ny)
    col = vm.index[np.clip(i, 0, nx - 1), np.clip(j, 0, ny - 1), :]  # (..., nz)
    has = col >= 0
    top = nz - 1 - np.argmax(has[..., ::-1], axis=-1)
    vox = np.take_along_axis(col, top[..., None], axis=-1)[..., 0].astype(np.int64)
    vox[~(ok & has.any(axis=-1))] = -1
    cnt = np.where(vox >= 0, count(np.asarray(amap))[np.maximum(vox, 0)], 0)
    return vox, cnt


@dataclass
class AccessResult:
    """Everything ``zmap access`` computes, saved as one ``.npz``."""

    vm: VoxelMap
    vg: np.ndarray
    amap: np.ndarray
    tool: Tool
    verdict: dict
    setups: list
    seconds: dict
    source: str = ""
    #: optional per z-map node arrays (``node_voxel``, ``node_count``) and their grid
    nodes: dict = field(default_factory=dict)
    #: ``V'_g`` of each piece of ``vm.pieces`` (a face in a voxel where several meet), or None
    vg_pieces: np.ndarray | None = None
    #: ``V'_g`` of each half-voxel piece of ``vm.fine`` (:func:`global_visibility` with
    #: ``refine=True``), or None
    vg_fine: np.ndarray | None = None
    #: ``A'`` of each piece of ``vm.pieces`` (:func:`accessibility` with ``pieces``), or None
    amap_pieces: np.ndarray | None = None

    def summary(self) -> str:
        """A markdown table of the verdict and the set-ups."""
        v = self.verdict
        tot = v["area_total"]
        lines = ["| figure | value |", "|---|---:|",
                 f"| surface area | {tot:,.1f} mm^2 |",
                 f"| reachable from +z (3-axis) | {v['area_reachable']:,.1f} mm^2 ({100 * v['share']:.1f} %) |",
                 f"| reachable only from other directions | {v['area_other']:,.1f} mm^2 "
                 f"({100 * v['area_other'] / tot if tot else 0:.1f} %) |",
                 f"| inaccessible with this tool | {v['area_inaccessible']:,.1f} mm^2 "
                 f"({100 * v['area_inaccessible'] / tot if tot else 0:.1f} %) |",
                 f"| set-ups found | {len(self.setups)} |"]
        acc = v["area_reachable"] + v["area_other"]
        run = 0.0
        for need in (0.9, 0.99):
            n = 0
            run = 0.0
            for s in self.setups:
                run += s["area"]
                n += 1
                if run >= need * acc:
                    break
            lines.append(f"| set-ups for {100 * need:.0f} % of the accessible area | {n} |")
        out = "\n".join(lines) + "\n\n| set-up | direction (x, y, z) | tilt from +z (deg) | area (mm^2) |\n|---:|---|---:|---:|\n"
        for i, s in enumerate(self.setups[:10]):
            x, y, z = s["vector"]
            out += (f"| {i + 1} | ({x:+.3f}, {y:+.3f}, {z:+.3f}) | {np.degrees(np.arccos(np.clip(z, -1, 1))):.1f} "
                    f"| {s['area']:,.1f} |\n")
        if len(self.setups) > 10:
            out += f"| ... | {len(self.setups) - 10} more | | {sum(s['area'] for s in self.setups[10:]):,.1f} |\n"
        return out

    def save(self, path) -> None:
        """Write atomically (temporary name, then rename)."""
        import json

        path = os.fspath(path)
        vm = self.vm
        setup_of = np.full(vm.n_boundary, -1, dtype=np.int32)
        for s, su in enumerate(self.setups):
            setup_of[su["voxels"]] = s
        header = {"format": "zmap.access", "version": 1, "d": vm.d, "q": vm.q, "step": vm.step,
                  "tool": vars(self.tool), "verdict": {k: v for k, v in self.verdict.items() if k != "reachable"},
                  "setups": [{k: v for k, v in s.items() if k != "voxels"} for s in self.setups],
                  "seconds": self.seconds, "flipped": vm.flipped}
        arrays = dict(origin=vm.origin, ijk=vm.ijk, state=vm.state, vl=vm.vl, light=vm.light, vg=self.vg,
                      amap=self.amap, curvature=vm.curvature, surface=vm.surface, point=vm.point,
                      normal=vm.normal, area=vm.area, setup=setup_of,
                      n_access=count(self.amap).astype(np.int32),
                      directions=vm.directions.normals,
                      header=np.frombuffer(json.dumps(header).encode(), dtype=np.uint8))
        if self.vg_pieces is not None and vm.pieces is not None and vm.pieces.face is not None:
            arrays.update(piece_voxel=vm.pieces.voxel, piece_face=vm.pieces.face, piece_vg=self.vg_pieces)
            if self.amap_pieces is not None:
                arrays.update(piece_amap=self.amap_pieces)
        if self.vg_fine is not None and vm.fine is not None:
            arrays.update(fine_voxel=vm.fine.voxel.astype(np.int32), fine_octant=vm.fine.octant.astype(np.uint8),
                          fine_face=vm.fine.face.astype(np.int32), fine_vg=self.vg_fine)
        for key, val in self.nodes.items():
            if isinstance(val, np.ndarray):
                arrays[key] = val
            else:
                header[key] = val
        arrays["header"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
        folder = os.path.dirname(os.path.abspath(path))
        fd, tmp = tempfile.mkstemp(dir=folder, prefix=".tmp-", suffix=".npz")
        os.close(fd)
        try:
            np.savez_compressed(tmp, **arrays)
            os.replace(tmp, path)
        except BaseException:
            if os.path.exists(tmp):
                os.unlink(tmp)
            raise


def _timer():
    t0 = time.perf_counter()
    return lambda: time.perf_counter() - t0
