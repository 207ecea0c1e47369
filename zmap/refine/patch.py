"""Verified EZ cells: test each refined cell against the exact surface, refine the misses.

The EZ-map's Coons patches hold a cell whose boundary carries one wall or one sharp edge.
Real dies also have cells that two walls cross, thin ribs, wall corners, and walls that
cross one grid edge twice; there the four boundary sequences do not determine the interior.
So :func:`zmap.refine.ez.build_ez` checks every refined cell at a lattice of test points
against the exact surface (:func:`misfit`), and gives each cell that misses a *cell
patch*: a finer z-map of ``m x m`` sub-cells over that one base cell whose every sub-edge
carries e-points (an EZ-map of its own), ``m = 2``, 4, 8, ... down to sub-cells of 6.25 tol
(2, 4 and 8 at grid 0.5 mm and tol 0.01 mm), cheapest first. A cell still off
(a wall, a chamfer and a fillet inside one sub-cell) gets the last resort, a dense lattice
of ``n x n`` intervals whose diagonal is at most ``tol``, interpolated bilinearly: a
bilinear height lies between the four corner heights, and the top-most surface (walls
included) passes through that height somewhere between those corners, so the model point
is within one diagonal, ``tol``, of the surface (as far as the sampler's heights are
exact), so lattice cells are not re-tested. ``EZMap.unresolved`` counts cells left off
when the lattice is not among the levels asked for (:func:`patch_failing`).

Storage (:class:`CellPatches`): per patched base cell its level ``m`` (``m > 0``: EZ
sub-grid; ``m = -n``: dense lattice), for a sub-grid the ``(m+1)^2`` heights of its nodes
and its e-points as 16-bit codes on one float32 offset and quantum per patch, with the
e-point count of each sub-edge (smooth sub-edges are thinned, as the e-map's edges are);
for a lattice its ``(n+1)^2`` heights as 16-bit codes with one offset and quantum. The
sub-edge ids are implicit (every sub-edge, in the e-map's id order), the offsets follow
from the levels and counts.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from ..grid import ZMap
from ._emap import (
    QUANTUM_SHARE,
    CellPatches,
    EZMap,
    SubLattices,
    all_edges,
    code_patch,
    decimate,
    encode_heights,
    sub_grid,
)

__all__ = ["BEND_RETEST", "PATCH_SUBCELLS", "SUB_TEST", "TEST_POINTS", "CellPatches", "SubLattices",
           "bending_cells", "build_sub_lattices", "cell_test_points",
           "failing_cells", "failing_subcells", "misfit", "patch_levels", "sub_lattice_intervals"]

#: finest sub-cell of the cell patches, in tolerances: the levels are 2, 4, 8, ... sub-cells
#: per base interval down to it (grid 0.5 mm, tol 0.01 mm: 2, 4, 8; grid 2 mm: 2, 4, ..., 32),
#: cheapest first (a level-m patch costs about 4 (m+1) h / tol bytes of codes)
PATCH_SUBCELLS = (6.25,)


def patch_levels(base: ZMap, tol: float, interval: float) -> tuple[int, ...]:
    """Sub-cells per base interval of each patch level (:data:`PATCH_SUBCELLS`), keeping a
    sub-cell at least three e-map intervals long."""
    h = min(base.dx, base.dy)
    finest = h / (PATCH_SUBCELLS[-1] * tol)
    # level 2 first: on the Ventilator (grid 0.5) it holds most of the cells that miss, at 60
    # codes a cell against a level-4 patch's 79
    levels = [2]
    while 2 * levels[-1] <= finest * (1 + 1e-9):
        levels.append(2 * levels[-1])
    return tuple(m for m in levels if h / m >= 3.0 * interval)
#: :func:`misfit`: a surface no steeper than this around a point is held to ``tol`` vertically
GENTLE_SLOPE = 1.0
#: test points per base interval and axis when a refined cell is checked (a lattice)
TEST_POINTS = 8
#: a cell is checked against this share of the tolerance, a margin for the points between
#: its test points
CHECK_SHARE = 0.9
#: a cell whose test lattice shows the model's error bending enough to pass the check's
#: tolerance between two test points (:func:`bending_cells`) is tested again on a lattice
#: this many times finer
BEND_RETEST = 4

Heights = Callable[[np.ndarray, np.ndarray], np.ndarray]


def misfit(h: np.ndarray, x: np.ndarray, y: np.ndarray, z_exact: np.ndarray, heights: Heights,
           tol: float) -> np.ndarray:
    """True where the model point ``(x, y, h)`` misses the exact surface by more than ``tol``.

    A point misses when its height is more than ``tol`` off the exact height and the exact
    heights around it (eight directions at ``tol/4``, ``tol/2`` and ``3 tol/4``) do not
    bracket it within ``tol/2``: where they do, the top-most surface passes within
    ``tol/2`` of the point's height within ``3 tol/4`` horizontally (on a face, or on a wall
    the model places off by that much), a 3D distance within ``0.9 tol``. A conservative
    stand-in for the 3D distance as far as the probes see. Where the surface is gentle (no
    probe rises or falls more than :data:`GENTLE_SLOPE` times its distance, and none is
    empty) the bracket does not excuse a point: there the vertical deviation itself is held
    to ``tol`` (Table 2's "max vertical deviation, not steep"). Gentle is judged along
    +-x and +-y, as Table 2 judges steep points: a plane rising 0.83 along x and along y
    (1.17 along the diagonal) is gentle (cornetta's 0.0102 mm vertical miss was there). A model height over no surface misses unless one of those
    neighbours has a surface; no model height (NaN) is never a miss (the base has none there).

    Parameters
    ----------
    h, x, y, z_exact : ndarray of shape (n,), float64
        Model heights, world xy and exact heights (NaN = no surface) of the points.
    heights : callable
        ``heights(x, y) -> z`` of the exact surface; called only for the points off vertically.
    tol : float
        Tolerance, mm.

    Returns
    -------
    ndarray of shape (n,), bool

    Examples
    --------
    >>> import numpy as np
    >>> f = lambda x, y: np.where(x > 1.0, 5.0, 0.0)
    >>> x, y = np.array([0.5, 0.995, 0.5]), np.zeros(3)
    >>> misfit(np.array([0.0, 2.5, 2.5]), x, y, f(x, y), f, 0.01).tolist()
    [False, False, True]
    """
    with np.errstate(invalid="ignore"):
        bad = np.isfinite(h) & ~(np.abs(h - z_exact) <= tol)
    idx = np.flatnonzero(bad)
    if idx.size:
        lo = z_exact[idx].copy()
        hi = z_exact[idx].copy()
        xi, yi = x[idx], y[idx]
        ang = np.arange(8) * (np.pi / 4)
        ox = np.concatenate([f * tol * np.cos(ang) for f in (0.25, 0.5, 0.75)])
        oy = np.concatenate([f * tol * np.sin(ang) for f in (0.25, 0.5, 0.75)])
        z2 = np.asarray(heights((xi[:, None] + ox).ravel(), (yi[:, None] + oy).ravel()),
                        dtype=np.float64).reshape(idx.size, ox.size)
        r = np.hypot(ox, oy)
        axis = np.tile(np.arange(8) % 2 == 0, 3)  # the +-x, +-y probes, as Table 2 tells steep points
        with np.errstate(invalid="ignore"):
            gentle = np.all(np.abs(z2[:, axis] - z_exact[idx, None]) <= GENTLE_SLOPE * r[axis], axis=1)
        with np.errstate(invalid="ignore"):
            lo = np.fmin(lo, np.nanmin(np.where(np.isnan(z2), np.inf, z2), axis=1))
            hi = np.fmax(hi, np.nanmax(np.where(np.isnan(z2), -np.inf, z2), axis=1))
        lo[~np.isfinite(lo)] = np.nan
        hi[~np.isfinite(hi)] = np.nan
        with np.errstate(invalid="ignore"):
            ok = (h[idx] >= lo - 0.5 * tol) & (h[idx] <= hi + 0.5 * tol) & ~gentle
        bad[idx[ok]] = False
    return bad


def cell_points(base: ZMap, cells: np.ndarray, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World xy of the lattice ``g x g`` (fractions of an interval) in each base cell.

    Returns two ndarrays of shape (len(cells) * len(g)**2,), cell-major, C order within a cell.
    """
    U, V = np.meshgrid(g, g, indexing="ij")
    ci, cj = np.divmod(np.asarray(cells, dtype=np.int64), base.ny - 1)
    lx = base.x0 + (ci[:, None] + U.ravel()[None, :]) * base.dx
    ly = base.y0 + (cj[:, None] + V.ravel()[None, :]) * base.dy
    return base.local_to_world(lx.ravel(), ly.ravel())


def cell_test_points(base: ZMap, cells: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """World xy of an ``n x n`` lattice inside each base cell (cell-centred, ``n*n`` per cell).

    Returns two ndarrays of shape (len(cells) * n * n,), cell-major.
    """
    return cell_points(base, cells, (np.arange(n) + 0.5) / n)


def bending_cells(error: np.ndarray, n: int, tol: float) -> np.ndarray:
    """Which cells' model error may pass ``tol`` between the test points of their lattice.

    Along a row or column of the lattice (spacing ``s``), an error ``e`` whose slope turns by
    ``k`` at one place between two test points rises at most ``k s / 4`` above their chord,
    and the second difference ``|e[i-1] - 2 e[i] + e[i+1]|`` at one of the two points
    beside the turn is at least ``k s / 2``; a smooth bend rises ``e'' s^2 / 8`` against a
    second difference of ``e'' s^2``. So the error between points is bounded by the three
    points' largest ``|e|`` plus half their second difference. A narrow crest the model
    rounds off between two test points (a fan blade's, 0.03 mm above a model that every
    point of an 8 x 8 lattice found within tol) shows as such a turn. A point more than
    ``tol`` off that :func:`misfit` excused (on a steep face or a wall, where its probes
    bracket the model's height) sends its cell on as well: the probes vouch for that point,
    not for the stretch to the next one (a fan blade's steep flank: 0.085 mm off at two
    test points, both excused, and 0.3 mm off between them). Empty points take no part.

    Parameters
    ----------
    error : ndarray of shape (n_cells * n * n,)
        Model height less exact height at :func:`cell_test_points` (NaN where either is empty).
    n : int
        Test lattice per cell and axis.
    tol : float
        Tolerance, mm.

    Returns
    -------
    ndarray of shape (n_cells,), bool

    Examples
    --------
    >>> import numpy as np
    >>> row = np.array([0.0, 0.001, 0.002, 0.008, 0.002, 0.001, 0.0, 0.0])  # a turn at the fourth point
    >>> bending_cells(np.tile(row, 8), 8, 0.01).tolist()
    [True]
    >>> bending_cells(np.tile(row / 4, 8), 8, 0.01).tolist()
    [False]
    """
    e = np.asarray(error, dtype=np.float64).reshape(-1, n, n)
    worst = np.zeros(e.shape[0])
    for ea in (e, e.transpose(0, 2, 1)):
        a, b, c = ea[:, :-2], ea[:, 1:-1], ea[:, 2:]
        bound = np.maximum(np.maximum(np.abs(a), np.abs(b)), np.abs(c)) + 0.5 * np.abs(a - 2.0 * b + c)
        worst = np.fmax(worst, np.nan_to_num(bound, nan=0.0).max(axis=(1, 2), initial=0.0))
    return worst > tol


def failing_cells(model_height: Heights, base: ZMap, heights: Heights, tol: float, cells: np.ndarray,
                  n: int = TEST_POINTS, bend: bool = False) -> np.ndarray:
    """The ``cells`` (flat base cell ids) where the model misses the exact surface at a test point.

    Parameters
    ----------
    model_height : callable
        ``model_height(x, y) -> h`` of the model under test, world xy.
    base : ZMap
        The base grid whose cells are tested.
    heights : callable
        Exact surface ``heights(x, y) -> z``.
    tol : float
        Tolerance, mm (:func:`misfit`).
    cells : ndarray of int64
        Flat cell ids ``i * (ny - 1) + j`` to test.
    n : int
        Test lattice per cell and axis.
    bend : bool
        Test the cells whose error bends between test points (:func:`bending_cells`) again
        on a lattice :data:`BEND_RETEST` times finer.

    Returns
    -------
    ndarray of int64
        Sorted ids of the cells with at least one miss.
    """
    cells = np.asarray(cells, dtype=np.int64)
    if cells.size == 0:
        return cells
    x, y = cell_test_points(base, cells, n)
    z = np.asarray(heights(x, y), dtype=np.float64)
    h = np.asarray(model_height(x, y), dtype=np.float64)
    bad = np.unique(cells[np.flatnonzero(misfit(h, x, y, z, heights, tol)) // (n * n)])
    if bend:
        again = np.setdiff1d(cells[bending_cells(h - z, n, tol)], bad)
        bad = np.union1d(bad, failing_cells(model_height, base, heights, tol, again, BEND_RETEST * n))
    return bad


def build_patches(base: ZMap, heights: Heights, cells: np.ndarray, m: int, interval: float,
                  tol: float, thin: float | None = None) -> dict[int, tuple]:
    """Patch data ``{cell: (m, nodes, codes, lo, step, counts)}`` of level ``m`` for ``cells``.

    Two calls of ``heights``: the sub-grid nodes of all cells, then their e-points. ``thin``
    (mm): thin the smooth sub-edges' e-points to that limit (:func:`zmap.refine._emap.decimate`).
    """
    from . import _ez_kernels as _k

    cells = [int(c) for c in np.asarray(cells, dtype=np.int64)]
    if not cells:
        return {}
    subs = [sub_grid(base, c, m) for c in cells]
    g = np.arange(m + 1, dtype=np.float64)
    GX, GY = np.meshgrid(g, g, indexing="ij")
    lx = np.concatenate([s.x0 + GX.ravel() * s.dx for s in subs])
    ly = np.concatenate([s.y0 + GY.ravel() * s.dy for s in subs])
    zn = np.asarray(heights(*base.local_to_world(lx, ly)), dtype=np.float64).reshape(len(cells), m + 1, m + 1)
    skel = []
    px_l, py_l = [], []
    for s, z in zip(subs, zn):
        s.z[...] = z
        ids, offsets = all_edges(s, interval)
        P = int(offsets[-1])
        ez = EZMap(s.x0, s.y0, s.dx, s.dy, m + 1, m + 1, interval, tol, ids, offsets, np.zeros(P, np.uint16),
                   np.zeros(ids.size, np.float32), np.zeros(ids.size, np.float32))
        px, py = ez.points()
        skel.append((s, ids, offsets))
        px_l.append(px)
        py_l.append(py)
    ze = np.asarray(heights(*base.local_to_world(np.concatenate(px_l), np.concatenate(py_l))), dtype=np.float64)
    out = {}
    at = 0
    for c, (s, ids, offsets) in zip(cells, skel):
        P = int(offsets[-1])
        z = np.ascontiguousarray(ze[at:at + P])
        at += P
        lifted = np.zeros(ids.size, dtype=np.int64)
        _k.despike(s.z, ids, offsets, z, tol, lifted)
        if thin is not None:
            offsets, z, _ = decimate(s.z, s.dx, s.dy, interval, tol, ids, offsets, z, thin, bare=True)
        out[c] = code_patch(m, s.z, z, np.diff(offsets), QUANTUM_SHARE * tol)
    return out


def lattice_intervals(base: ZMap, tol: float) -> int:
    """Intervals per side of a cell's dense lattice whose diagonal is at most ``tol``."""
    return max(1, math.ceil(math.hypot(base.dx, base.dy) / tol - 1e-9))


def build_lattices(base: ZMap, heights: Heights, cells: np.ndarray, n: int, quantum: float = 0.0) -> dict[int, tuple]:
    """Dense lattice patch data ``{cell: (-n, nodes, codes, lo, step)}`` (one ``heights`` call),
    coded no finer than ``quantum`` (:func:`zmap.refine._emap.encode_heights`)."""
    cells = [int(c) for c in np.asarray(cells, dtype=np.int64)]
    if not cells:
        return {}
    wx, wy = cell_points(base, np.array(cells, dtype=np.int64), np.arange(n + 1, dtype=np.float64) / n)
    z = np.asarray(heights(wx, wy), dtype=np.float64).reshape(len(cells), -1)
    P = (n + 1) ** 2
    out = {}
    for c, zc in zip(cells, z):
        codes, lo, step = encode_heights(np.array([0, P], dtype=np.int64), zc, quantum)
        out[c] = (-n, np.zeros(0), codes, lo, step)
    return out


#: test points per sub-cell and axis when the sub-cells of a patch that misses are tested
SUB_TEST = 4


def failing_subcells(model_height: Heights, base: ZMap, heights: Heights, tol: float, cells: np.ndarray, m: int,
                     n: int = SUB_TEST) -> np.ndarray:
    """Keys ``cell * m * m + si * m + sj`` of the level-``m`` sub-cells of ``cells`` where the
    model misses at one of an ``n x n`` lattice of test points (:func:`misfit`), sorted."""
    cells = np.asarray(cells, dtype=np.int64)
    if cells.size == 0:
        return cells
    G = m * n
    x, y = cell_points(base, cells, (np.arange(G) + 0.5) / G)
    bad = np.flatnonzero(misfit(np.asarray(model_height(x, y), dtype=np.float64), x, y,
                                np.asarray(heights(x, y), dtype=np.float64), heights, tol))
    c, r = np.divmod(bad, G * G)
    a, b = np.divmod(r, G)
    return np.unique(cells[c] * m * m + (a // n) * m + b // n)


def sub_lattice_intervals(base: ZMap, tol: float, m: int) -> int:
    """Intervals per side of a level-``m`` sub-cell's lattice whose diagonal is at most ``tol``."""
    return max(1, math.ceil(math.hypot(base.dx, base.dy) / m / tol - 1e-9))


def build_sub_lattices(base: ZMap, heights: Heights, keys: np.ndarray, m: int, n: int,
                       quantum: float = 0.0) -> SubLattices:
    """Dense ``n x n`` lattices over the level-``m`` sub-cells ``keys`` (one ``heights`` call),
    coded no finer than ``quantum``."""
    keys = np.asarray(keys, dtype=np.int64)
    cell, r = np.divmod(keys, m * m)
    si, sj = np.divmod(r, m)
    ci, cj = np.divmod(cell, base.ny - 1)
    t = np.arange(n + 1) / n
    U, V = np.meshgrid(t, t, indexing="ij")
    lx = base.x0 + (ci[:, None] + (si[:, None] + U.ravel()[None, :]) / m) * base.dx
    ly = base.y0 + (cj[:, None] + (sj[:, None] + V.ravel()[None, :]) / m) * base.dy
    z = np.asarray(heights(*base.local_to_world(lx.ravel(), ly.ravel())), dtype=np.float64)
    codes, lo, step = encode_heights(np.arange(keys.size + 1, dtype=np.int64) * (n + 1) ** 2, z, quantum)
    return SubLattices(np.array([m, n]), keys, codes, lo, step, quantum)


def _sub_lattices(model_height: Heights, base: ZMap, heights: Heights, tol: float, tol_check: float,
                  bad: np.ndarray, m: int) -> tuple[SubLattices | None, np.ndarray]:
    """Sub-lattices over the missing sub-cells of the level-``m`` patches of ``bad``, for the
    cells where they cost less than a whole-cell lattice; returns them and the cells that
    need the whole-cell lattice."""
    keys = failing_subcells(model_height, base, heights, tol_check, bad, m)
    n = sub_lattice_intervals(base, tol, m)
    whole_bytes = 2 * (lattice_intervals(base, tol) + 1) ** 2
    cells, count = np.unique(keys // (m * m), return_counts=True)
    cheap = cells[count * (2 * (n + 1) ** 2 + 16) < whole_bytes]
    # a cell none of whose sub-cells misses on the finer test lattice keeps its patch
    whole = np.setdiff1d(np.intersect1d(bad, cells), cheap)
    keys = keys[np.isin(keys // (m * m), cheap)]
    return (build_sub_lattices(base, heights, keys, m, n, QUANTUM_SHARE * tol) if keys.size else None), whole


def patch_failing(model_height: Heights, base: ZMap, heights: Heights, tol: float, interval: float,
                  cells: np.ndarray, set_patches: Callable[[CellPatches], None],
                  levels: tuple[int, ...] | None = None, n: int = TEST_POINTS,
                  fine_cells: np.ndarray | None = None, lattice: bool = True,
                  thin: float | None = None,
                  bubbles: Callable[[np.ndarray], np.ndarray] | None = None) -> tuple[CellPatches, np.ndarray]:
    """Test ``cells``, patch the misses level by level; returns the patches and the cells still off.

    ``set_patches`` installs a :class:`CellPatches` in the model that ``model_height``
    evaluates, so each level is tested as the model will answer. ``fine_cells`` (a subset
    of ``cells``: those a wall or an edge runs through) are tested on a lattice four times as
    fine: a Coons cell split along a wall can miss by a sliver next to the wall that an
    ``n x n`` lattice steps over. ``levels`` (default :func:`patch_levels`) are the EZ patch
    levels tried in turn; ``lattice`` adds the dense lattice as the last resort; ``thin``
    (mm) thins the patches' smooth sub-edges (:func:`build_patches`). ``bubbles(bad)``, called
    with the cells that miss before any patch is built, may fix some more cheaply (the
    EZ-map's bubbles, :func:`zmap.refine.ez.build_ez`) and returns those still missing.
    """
    per_cell: dict[int, tuple] = {}
    tol_check = CHECK_SHARE * tol
    levels = patch_levels(base, tol, interval) if levels is None else tuple(
        m for m in levels if min(base.dx, base.dy) / m >= 3.0 * interval)
    cells = np.asarray(cells, dtype=np.int64)
    if fine_cells is not None and len(fine_cells):
        fine = np.isin(cells, fine_cells)
        bad = np.union1d(failing_cells(model_height, base, heights, tol_check, cells[~fine], n, bend=True),
                         failing_cells(model_height, base, heights, tol_check, cells[fine], 4 * n))
    else:
        bad = failing_cells(model_height, base, heights, tol_check, cells, n, bend=True)
    if bubbles is not None and bad.size:
        bad = np.asarray(bubbles(bad), dtype=np.int64)
    patches = CellPatches.empty()
    for m in levels + ((0,) if lattice else ()):
        if bad.size == 0:
            break
        if m:
            per_cell.update(build_patches(base, heights, bad, m, interval, tol, thin))
        else:  # the last resort: lattices whose cells' diagonal is tol
            subs = None
            whole = bad
            if levels:
                # over the sub-cells of the finest patch that miss, if cheaper than the whole cell
                subs, whole = _sub_lattices(model_height, base, heights, tol, tol_check, bad, levels[-1])
            per_cell.update(build_lattices(base, heights, whole, lattice_intervals(base, tol), QUANTUM_SHARE * tol))
        patches = CellPatches.pack(per_cell)
        if not m and subs is not None:
            keep = np.isin(subs.keys // (levels[-1] ** 2), patches.cells[patches.level > 0])
            patches.subs = SubLattices(subs.mn, subs.keys[keep], subs.codes.reshape(subs.n, -1)[keep].ravel(),
                                       subs.lo[keep], subs.step[keep], subs.quantum)
        set_patches(patches)
        if not m:
            # within tol by construction (module docstring); the probes of misfit reach
            # 0.75 tol, so a re-test would flag points up to tol from a wall
            return patches, np.zeros(0, dtype=np.int64)
        # a patch is tested on a finer lattice: its sub-cells are smaller, and a wall or a
        # crest left inside one misses in a band narrower than the coarse lattice steps over
        # (the Ventilator's blade crests: 0.017 mm off vertically in a level-8 patch that a
        # 16 x 16 test passed); no coarser than the first test of a cell a break runs through
        bad = failing_cells(model_height, base, heights, tol_check, bad, max(4 * n, 2 * m), bend=True)
    return patches, bad

