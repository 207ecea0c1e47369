"""Building the visibility voxel map (paper 002 §4.3-4.4): samples binned into voxels, the
material rule that makes the interior (paint spreading for a closed shell, or the solid below
the top surface for an open die face), the model checks and the uncertain voxels.

The casting lives in :mod:`zmap.access.casting`, the tool in :mod:`zmap.access.tool`, the
answers in :mod:`zmap.access.result`; :mod:`zmap.access.voxelmap` gathers them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ._common import AccessModelError, _ranges  # noqa: F401  (re-exported: the access modules raise it)
from .directions import DirectionSet, direction_set

EXTERIOR, BOUNDARY, INTERIOR, UNPAINTED = 0, 1, 2, 3
#: Largest number of voxels a map may hold (about 1 GB of state and index arrays).
MAX_VOXELS = 200_000_000


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
    solid : str
        The rule that made the interior: ``'closed'`` (paint spreading) or ``'below'`` (the
        material below the top surface, down to ``floor``); ``solid_note`` says it in words.
    uncertain : ndarray of shape (mb,), bool
        Voxels whose side the map cannot tell (:mod:`zmap.access.solid`): their whole cube
        blocks every direction in the casting; ``uncertain_info`` their figures.
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
    solid: str = "closed"
    solid_note: str = "closed shell (paint spreading)"
    floor: float = float("nan")
    uncertain: np.ndarray | None = None
    uncertain_info: dict = field(default_factory=dict)

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
                     pad: int = 2, check: bool = True, fine: bool = True, solid: str = "closed",
                     floor: float | None = None, max_uncertain: float | None = None,
                     solid_note: str = "") -> "VoxelMap":
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
            Apply the model checks (raise :class:`AccessModelError` on failure) and find the
            uncertain voxels.
        fine : bool
            Also build ``fine``, the half-voxel pieces that :func:`global_visibility` casts with
            ``refine=True`` (default True).
        solid : {'closed', 'below', 'auto'}
            The rule that makes the interior (:mod:`zmap.access.solid`): ``closed`` (default)
            the paper's paint spreading, which needs a closed shell; ``below`` the material
            below the top-most surface seen from +z, down to the lowest sample or ``floor`` (an
            open die face); ``auto`` closed, or below where the paint leaks through the shell.
        floor : float, optional
            The material's lowest z (mm) with ``below``; at most the lowest sample's (default:
            two voxels below it, so that the lowest faces stand on material too).
        max_uncertain : float, optional
            Largest share of the boundary area that may be uncertain (0.25 by default;
            :data:`zmap.access.solid.MAX_UNCERTAIN`); a map with more raises.
        solid_note : str
            Why the caller chose ``solid`` (shown in the summary), e.g. the free edges of an
            open model.
        """
        from ._access_kernels import (accumulate, orientation_votes, paint_exterior, patch_slab,
                                      piece_accumulate)
        from ._solid_kernels import below_top, sample_sides
        from .solid import MAX_UNCERTAIN, check_solid, kfloor_of, refusal, top_heights, uncertain_report

        d = check_voxel_size(d)
        solid, floor = check_solid(solid, floor)
        max_uncertain = MAX_UNCERTAIN if max_uncertain is None else float(max_uncertain)
        if not (0 <= max_uncertain <= 1):
            raise AccessModelError(f"max_uncertain must be a share in [0, 1], got {max_uncertain!r}")
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
        zmin = float(lo[2])
        if floor is not None and floor > zmin:
            raise AccessModelError(f"floor z = {floor:g} mm is above the part's lowest point z = {zmin:.3f} mm: "
                                   "the material below the top surface must hold every face")
        # the material below an open surface reaches under its lowest point by _UNDER voxels
        # (the lowest faces stand on material too), or down to the floor
        base = zmin - _UNDER * d if floor is None else floor
        if solid != "closed":
            lo = lo.copy()
            lo[2] = base
        origin = lo - pad * d
        shape = tuple(int(s) for s in np.floor((hi - origin) / d).astype(np.int64) + pad + 1)
        refuse_oversized(shape, d)
        ijk = np.floor((pts - origin) / d).astype(np.int64)
        flat = (ijk[:, 0] * shape[1] + ijk[:, 1]) * shape[2] + ijk[:, 2]
        uniq, vox = np.unique(flat, return_inverse=True)
        state = np.full(shape, UNPAINTED, dtype=np.uint8)
        state.ravel()[uniq] = BOUNDARY
        index = np.full(shape, -1, dtype=np.int32)
        index.ravel()[uniq] = np.arange(len(uniq), dtype=np.int32)
        bijk = np.stack(np.unravel_index(uniq, shape), axis=1).astype(np.int32)
        paint_exterior(state)
        step_ = float(step) if step is not None else 0.25 * d
        flipped: list[int] = []
        nf = int(fid.max()) + 1
        rule = solid
        if solid == "auto":
            rule = "closed" if np.any(state == INTERIOR) else "below"
            if rule == "below" and not solid_note:
                solid_note = f"the paint leaked through the shell at d = {d:g} mm"
        if rule == "below":
            kfloor = kfloor_of(base, float(origin[2]), d)
            below_top(state, kfloor, top_heights(pts, origin, d, shape, step_), float(origin[2]), d)
            note = (f"below the top surface seen from +z, down to z = {base:.3f} mm"
                    f" ({solid_note or 'asked'})")
        else:
            note = "closed shell (paint spreading)" + (f" ({solid_note})" if solid_note else "")
        if check and rule == "closed":
            _check_connected(state, index, fid, vox, pts)
            if not np.any(state == INTERIOR):
                raise AccessModelError(
                    f"no interior voxels at d = {d:g} mm: the exterior paint leaks through the "
                    f"shell (an open surface, a gap wider than {d:g} mm, or walls thinner than the "
                    "voxel); the paper needs a closed model at the voxel resolution (an open die face: "
                    "--solid below takes the material below its top surface)")
        flags = np.zeros(n, dtype=np.uint8)
        if check:
            votes = np.zeros((nf, 4), dtype=np.int64)
            orientation_votes(pts, nrm, fid, origin, d, state, votes)
            flipped = _orient(votes)
            nrm = nrm.copy()
            if flipped:
                turn = np.isin(fid, flipped)
                nrm[turn] *= -1
                kmax = np.where(turn, -kmax, kmax)  # concave and convex swap with the side
            sample_sides(pts, nrm, origin, d, _REACH * d, state, flags)
            # a sample with interior in front and exterior behind points inward: turned alone
            inward = flags == 3
            nrm[inward] *= -1
            kmax = np.where(inward, -kmax, kmax)
        mb = len(uniq)
        W = ds.words
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
        unc = np.zeros(mb, dtype=bool)
        unc[vox[flags != 0]] = True
        if unc.any():
            light[unc] = vl_all(ds)  # an uncertain voxel blocks every direction
        vm = cls(origin=origin, d=d, state=state, index=index, ijk=bijk, vl=vl, light=light,
                 curvature=curv, surface=surf, crease=crease.astype(bool), point=point,
                 normal=normal, area=area, q=ds.q, flipped=flipped,
                 step=float(step) if step is not None else float("nan"), n_samples=n,
                 box_lo=box_lo, box_hi=box_hi, slab=slab, tight_lo=tight_lo, tight_hi=tight_hi,
                 pieces=pieces, fine=fine_pieces, solid=rule, solid_note=note,
                 floor=base if rule == "below" else float("nan"),
                 uncertain=unc)
        vm.uncertain_info = uncertain_report(vm, flags, vox, pts, nrm, fid)
        if check and vm.uncertain_info["share"] > max_uncertain:
            raise AccessModelError(refusal(vm, max_uncertain))
        return vm

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
        boxes), the pieces of the others (all voxels where no pieces are known), and last the
        uncertain voxels, each its whole cube with every direction in ``light`` and no slab.

        Returns
        -------
        centre, half : (nb, 3) box centres and half extents; voxel : (nb,) int64;
        light : (nb, words) uint64; plane : (nb, 7) mean point, unit normal and slab.
        """
        c, h = self.boxes(tight=True)
        plane = np.concatenate([self.point, self.normal, self.slabs()[:, None]], axis=1)
        one, pk, unc = self._blocker_rows()
        parts = [(c[one], h[one], one, self.light[one], plane[one])]
        if pk is not None:
            p = self.pieces
            pplane = np.concatenate([p.point, p.normal, p.slab[:, None]], axis=1)
            parts.append((0.5 * (p.lo[pk] + p.hi[pk]), 0.5 * (p.hi[pk] - p.lo[pk]), p.voxel[pk], p.light[pk],
                          pplane[pk]))
        if len(unc):
            uplane = np.zeros((len(unc), 7))
            uplane[:, :3] = self.centres[unc]
            uplane[:, 6] = np.inf
            parts.append((self.centres[unc], np.full((len(unc), 3), 0.5 * self.d), unc, self.light[unc], uplane))
        return tuple(np.concatenate([x[i] for x in parts]) if i != 2 else
                     np.concatenate([x[2] for x in parts]).astype(np.int64) for i in range(5))

    def _blocker_rows(self) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        """The rows of :meth:`blockers`: the voxels taken by their own box, the pieces (None
        where no pieces are known) and the uncertain voxels."""
        unc = self.uncertain if self.uncertain is not None else np.zeros(self.n_boundary, dtype=bool)
        if self.pieces is None:
            return np.flatnonzero(~unc), None, np.flatnonzero(unc)
        return (np.flatnonzero((self.surface >= 0) & ~unc), np.flatnonzero(~unc[self.pieces.voxel]),
                np.flatnonzero(unc))

    def orient(self, points, normals, face) -> np.ndarray:
        """Normals (n, 3) of other samples of the same faces as the map turned them: the faces
        of ``flipped`` turned, and a sample with interior in front of it and exterior behind it
        (:func:`~zmap.access._solid_kernels.sample_sides`) turned alone."""
        from ._solid_kernels import sample_sides

        pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        nrm = np.array(normals, dtype=np.float64).reshape(-1, 3)
        if self.flipped:
            nrm[np.isin(np.asarray(face).ravel(), self.flipped)] *= -1
        flags = np.zeros(len(pts), dtype=np.uint8)
        sample_sides(pts, nrm, np.ascontiguousarray(self.origin, dtype=np.float64), float(self.d), _REACH * self.d,
                     self.state, flags)
        nrm[flags == 3] *= -1
        return nrm

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


def refuse_oversized(shape, d: float) -> None:
    """Refuse a voxel grid of ``shape`` at edge ``d`` with more than :data:`MAX_VOXELS` voxels,
    naming the smallest voxel that fits."""
    total = float(np.prod(np.asarray(shape, dtype=np.float64)))
    if total > MAX_VOXELS:
        raise AccessModelError(f"{shape[0]} x {shape[1]} x {shape[2]} = {int(total):,} voxels at d = {d:g} mm "
                               f"exceed the limit of {MAX_VOXELS:,}: choose a larger --voxel (at least "
                               f"{d * (total / MAX_VOXELS) ** (1 / 3):.2g} mm)")


def check_voxel_size(d) -> float:
    """``d`` as a float, AccessModelError unless it is a positive number of mm."""
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


def _orient(votes) -> list[int]:
    """Faces to turn: those whose samples point into the interior more often than out of it
    (``orientation_votes``); the samples of a face that disagree with its majority make their
    voxels uncertain (:mod:`zmap.access.solid`) instead of failing the part."""
    return [int(f) for f in np.flatnonzero(votes[:, 1] > votes[:, 0])]


#: how far (in voxel edges) below the lowest sample the material below an open surface reaches
#: without a floor
_UNDER = 2.0
#: how far (in voxel edges) a sample looks along its normal, each way, for the first voxel off
#: the boundary (:func:`~zmap.access._solid_kernels.sample_sides`)
_REACH = 3.0


def vl_all(ds: DirectionSet) -> np.ndarray:
    """The bitset (words,) uint64 of every direction of ``ds``."""
    out = np.full(ds.words, np.uint64(0xFFFFFFFFFFFFFFFF), dtype=np.uint64)
    if ds.k % 64:
        out[-1] = np.uint64((1 << (ds.k % 64)) - 1)
    return out




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
