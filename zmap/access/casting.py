"""Cylinder casting (paper 002 §4.5): ``V'_g`` of every boundary voxel, its pieces and, with
the refinement, its half-voxel pieces."""

from __future__ import annotations

import numpy as np

from .build import VoxelMap, _octant_lo
from .directions import DirectionSet, count

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
                      refine: bool = False, stats: dict | None = None) -> np.ndarray | tuple[np.ndarray, ...]:
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

    An uncertain voxel (``vm.uncertain``: a wall or gap thinner than the voxel) blocks as its
    whole cube every direction; as a query it skips its own cube, and so do its pieces, and the
    refinement leaves its half-voxel pieces with its own bits.

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

    ``stats``, a dict, receives the refinement's figures: half-voxel ``pieces``, those
    ``cast`` again, (piece, direction) ``pairs`` cast again, pairs ``freed``, and
    ``voxel_pairs_freed`` and ``piece_pairs_freed``.

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
        pid = -3 - np.arange(len(p.voxel), dtype=np.int64)  # skip nothing as itself
        plight = p.light
        if vm.uncertain is not None and vm.uncertain.any():
            # a piece of an uncertain voxel skips its voxel's cube, as the voxel does
            pu = vm.uncertain[p.voxel]
            pid = np.where(pu, p.voxel, pid)
            plight = np.where(pu[:, None], vm.light[p.voxel], p.light)
        qid = np.concatenate([qid, pid])
        light, vl = np.concatenate([light, plight]), np.concatenate([vl, p.vl])
        ppt, pnrm, slab = np.concatenate([ppt, p.point]), np.concatenate([pnrm, p.normal]), np.concatenate([slab, p.slab])
    out = _cast(vm, cast, qx, qh, qid, light, vl, ppt, pnrm, slab, vm.d / rays, tile=_TILE)
    bits = np.empty((len(qx), ds.words), dtype=np.uint64)
    pack_columns(out, bits)
    del out
    if refine and vm.fine is not None and vm.fine.octant is not None:
        vb, pb = bits[:mb], (bits[mb:] if extra else np.zeros((0, ds.words), dtype=np.uint64))
        vb, pb, fb = _refine(vm, cast, vb, pb, rays, stats=stats)
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


#: the refinement casts a half-voxel piece's direction only where a boundary voxel within this
#: many voxels (along each axis) keeps it; -1: everywhere (tests)
_REFINE_NEAR = 1


def _refine(vm: VoxelMap, cast: tuple, vb: np.ndarray, pb: np.ndarray, rays: int, near: int | None = None,
            tile: int | None = None, stats: dict | None = None):
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
    if vm.uncertain is not None:
        need[vm.uncertain[f.voxel]] = 0  # an uncertain voxel keeps what its cube's cast keeps
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
    if stats is not None:
        stats.update(pieces=int(nfine), cast=int(len(todo)), pairs=int(count(need).sum()),
                     freed=int(count(got).sum()), voxel_pairs_freed=int(count(vb).sum() - vb0),
                     piece_pairs_freed=int((count(pb).sum() if len(pb) else 0) - pb0))
    return vb, pb, fb
