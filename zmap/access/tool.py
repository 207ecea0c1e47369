"""The ball-end tool (paper 002 §4.6): the accessibility map ``A'`` with shank and holder."""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from .build import AccessModelError, VoxelMap
from .casting import _merged_blockers, _opposite
from .directions import DirectionSet

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


def _tally(counts: np.ndarray, stats: dict | None) -> None:
    """Add a tool test's per-direction ``counts`` to ``stats``: the pairs the dilated buffers
    decided as ``clear``, as ``blocked``, and those ``scanned`` on the disc (shank and holder
    tests together)."""
    if stats is not None:
        for key, n in zip(("clear", "blocked", "scanned"), counts.sum(axis=0)):
            stats[key] = stats.get(key, 0) + int(n)


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
                  samples: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
                  vg_pieces: np.ndarray | None = None,
                  stats: dict | None = None) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
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

    With samples, an uncertain voxel (``vm.uncertain``) keeps only the directions its own
    cast keeps too (``vg``; its pieces those of ``vg_pieces``, the pieces' ``V'_g`` of
    :func:`global_visibility`, or none without it), and the tool is also tested against points
    on the faces that interior voxels share with exterior ones
    (:func:`zmap.access.solid.open_walls`: the sides and floor of the material below an open
    surface, which has no samples there).

    Without samples, no blocker may reach above the ball's centre within the shank's radius, nor
    above the stick-out within the holder's radius (both tested upward without end; cells of
    the depth buffers: ``cell``, d by default, and ``cell_holder``, the larger of d and a fifth
    of the holder's radius; see :func:`tool_clearance`), and a voxel where the ball itself
    would hold a boundary or interior voxel centre closer than a - half a diagonal to its
    centre has no direction. ``stats``, a dict, gathers the tool test's figures
    (:func:`tool_clearance`).

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
        return tool_clearance(vm, np.ascontiguousarray(local), tool, cell=cell, cell_holder=cell_holder, stats=stats)
    if samples is not None:
        return _sampled_access(vm, tool, bad, pieces, samples, cell, vg, vg_pieces, stats=stats)
    fits = np.empty(vm.n_boundary, dtype=np.bool_)
    ball_fits(centre, vm.origin, vm.d, vm.state, a - hd, fits)
    # not ANDed with V'_g: the capsule holds the thin ray, and the cast's voxel-wide cylinders
    # lose grazing directions at convex edges that the tool clears (featuretype: 0.5 % of pairs)
    local = np.where((fits & (bad & 1 == 0))[:, None], vm.vl, np.uint64(0))
    p = vm.pieces
    if not _has_pieces(vm, pieces):
        return _split_pieces(vm, tool_clearance(vm, np.ascontiguousarray(local), tool, cell=cell,
                                                cell_holder=cell_holder, stats=stats), pieces)
    # the pieces ride along as more queries of the same buffers
    pcentre = np.ascontiguousarray(p.point + a * p.normal)
    pfits = np.empty(len(p.voxel), dtype=np.bool_)
    ball_fits(pcentre, vm.origin, vm.d, vm.state, a - hd, pfits)
    plocal = np.where((pfits & ~_curved(vm, a)[p.voxel])[:, None], p.vl, np.uint64(0))
    both = tool_clearance(vm, np.ascontiguousarray(np.concatenate([local, plocal])), tool, cell=cell,
                          cell_holder=cell_holder, stats=stats,
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
                    cell: float | None, vg: np.ndarray | None = None,
                    vg_pieces: np.ndarray | None = None,
                    stats: dict | None = None) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """:func:`accessibility` by the capsule on the surface samples (its ``samples``)."""
    from scipy.spatial import cKDTree

    from .solid import open_walls

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
    # the material's sides and floor without samples (below an open surface) block as they do
    walls = open_walls(vm)
    if len(walls):
        spts = np.ascontiguousarray(np.concatenate([spts, walls]))
        tree = cKDTree(spts)
    # the ball fits: no sample closer than a (less OCC's 1e-3 mm) to its centre
    dist, _ = tree.query(qp + a * qn, workers=-1)
    local[dist < a - 1e-3] = 0
    unc = vm.uncertain
    if unc is not None and unc.any() and vg is not None:
        # an uncertain voxel keeps only what its own cast keeps too
        mb = vm.n_boundary
        local[:mb][unc] &= np.asarray(vg, dtype=np.uint64)[unc]
        if len(local) > mb:
            pu = np.flatnonzero(unc[p.voxel])
            local[mb + pu] = (local[mb + pu] & np.asarray(vg_pieces, dtype=np.uint64)[pu]) if vg_pieces is not None \
                else 0
    both = tool_clearance(vm, np.ascontiguousarray(local), tool, cell=cell,
                          queries=(qp, qn, np.full(len(qp), -1)), samples=spts, stats=stats)
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
    """The face of each of :meth:`VoxelMap.blockers` (nb,) int64 (-1: several, or uncertain)."""
    one, pk, unc = vm._blocker_rows()
    parts = [vm.surface[one].astype(np.int64)]
    if pk is not None:
        pf = vm.pieces.face if vm.pieces.face is not None else np.full(len(vm.pieces.voxel), -1)
        parts.append(np.asarray(pf, dtype=np.int64)[pk])
    parts.append(np.full(len(unc), -1, dtype=np.int64))
    return np.concatenate(parts)


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
                   samples: np.ndarray | None = None, stats: dict | None = None) -> np.ndarray:
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

    ``stats``, a dict, gathers the pairs the dilated buffers decided as ``clear``, as
    ``blocked``, and those ``scanned`` on the disc (added to counts already there).
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
                                 float(cell or vm.d), stats)
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
    counts = np.zeros((ds.k, 3), dtype=np.int64)
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
                out, counts)
    _tally(counts, stats)
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
                      cell: float, stats: dict | None = None) -> np.ndarray:
    """:func:`tool_clearance` on the surface samples (its ``samples``): (mb, words) uint64."""
    import numba

    from ._access_kernels import pack_columns
    from ._sample_kernels import sample_tool_kernel

    ds = vm.directions
    tol = 1e-3
    r_shank = tool.radius - tol
    r_holder = tool.holder_diameter / 2.0 - tol if tool.holder_diameter > 0 else 0.0
    out = np.zeros((ds.k, len(centre)), dtype=np.uint8)
    counts = np.zeros((ds.k, 3), dtype=np.int64)
    sample_tool_kernel(ds.normals, np.ascontiguousarray(local), centre, samples, r_shank,
                       tool.stickout - tool.radius, r_holder, cell, _disc_rows(r_shank / cell, outer=True),
                       _covered_rows(r_shank / cell), _disc_rows(max(r_holder, 0.0) / cell, outer=True),
                       _covered_rows(max(r_holder, 0.0) / cell), out, counts, numba.get_num_threads(),
                       *_direction_pairs(ds))
    _tally(counts, stats)
    bits = np.empty((len(centre), ds.words), dtype=np.uint64)
    pack_columns(out, bits)
    return bits
