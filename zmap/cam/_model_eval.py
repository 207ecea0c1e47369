"""numba entry to a precision model's heights: the drop-cutter samples a model through it.

:func:`pack_model` gathers the flat arrays of a :class:`zmap.model.PrecisionModel` (or a
plain :class:`zmap.ZMap`): the base map, the CZ-maps packed as :mod:`zmap._model_kernels`
packs them, the EZ-map's e-points and tables (taken through :class:`zmap.refine.ez.EZMap`'s
own ``_tables``/``_hq``/offsets, never re-derived, so that its storage can change under us)
and its EZ cell patches (each through ``CellPatches._patch_maps``: a patch is an EZ-map on a
sub-grid). :func:`height_at` answers one point inside numba with the model's rule: the CZ-map
in which the point lies deepest, else the EZ-map in an EZ cell (a patch where one covers the
cell), else the base's Bezier surface. The tests hold it to ``PrecisionModel.height``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numba.core import types
from numba.typed import List
from numba.experimental import structref

from .._interp_kernels import _bezier1d, _locate, _to_local, slope_tables
from .._model_kernels import bezier_at_tabled, deepest_cz
from ..refine import _ez_kernels as _ezk

__all__ = ["pack_model", "heights", "supported", "threaded"]


def threaded(kernel, n: int, *args, chunk: int = 256) -> None:
    """``kernel(*args, k0, k1)`` over ``0:n`` in chunks on numba's thread count of threads
    (the kernels hold no GIL); one thread for a single chunk. Each thread takes its own copy of
    a :class:`PackedModel` argument (:func:`_clone`): two threads reading the same arrays slowed
    each other down (an EZ height took 5.2 us on two threads against 1.6 us on one; a base
    height 0.53 us against 0.14 us), as the kernels count references to the arrays they read."""
    import numba

    nt = max(1, numba.get_num_threads())
    bounds = [(a, min(n, a + chunk)) for a in range(0, n, chunk)]
    if nt == 1 or len(bounds) <= 1:
        kernel(*args, 0, n)
        return
    from concurrent.futures import ThreadPoolExecutor

    workers = min(nt, len(bounds))
    own = [tuple(_clone(a) if isinstance(a, PackedModel) else a for a in args) for _ in range(workers)]

    def run(w):
        for a, b in bounds[w::workers]:
            kernel(*own[w], a, b)

    with ThreadPoolExecutor(max_workers=workers) as ex:
        for f in [ex.submit(run, w) for w in range(workers)]:
            f.result()


def _ez_arrays(ez, base):
    """``(z, par, edge_ids, offsets, hq, brk_kind, brk_t, ecell_ids, slots, nb, bk, bt, pts, arc, bub, plain)``
    of an EZ-map over ``base`` (its own tables and codes; ``plain``: :func:`_plain_slopes`)."""
    a = ez._tables(base)
    off = ez._voff() if hasattr(ez, "_voff") else ez.offsets
    par = np.array([base.x0, base.y0, base.dx, base.dy, math.cos(base.angle), math.sin(base.angle),
                    base.origin[0], base.origin[1]], dtype=np.float64)
    z = np.ascontiguousarray(base.z, dtype=np.float64)
    plain = np.full((len(a["ecell_ids"]), 4, 2), np.nan)
    _plain_slopes(z, a["ecell_ids"], a["slots"], ez.edge_ids, a["brk_kind"], base.dx, base.dy, plain)
    return (z, par, ez.edge_ids, off, ez._hq(), a["brk_kind"], a["brk_t"], a["ecell_ids"], a["slots"], a["nb"],
            a["bk"], a["bt"], a["pts"], a["arc"], a["bub"], plain)


@njit(cache=True)
def _plain_slopes(z, ecell_ids, slots, edge_ids, brk_kind, dx, dy, out):
    """``out[c, k]``: the end slopes of e-cell c's local edge k where it has no e-points
    (:func:`zmap.refine._ez_kernels.plain_edge_slopes`), made once: :func:`_ez_at` reads them
    instead of finding the edges' breaks and the slopes at every height."""
    ny = z.shape[1]
    for c in range(ecell_ids.shape[0]):
        i = ecell_ids[c] // (ny - 1)
        j = ecell_ids[c] % (ny - 1)
        for k in range(4):
            if slots[c, k] < 0:
                out[c, k, 0], out[c, k, 1] = _ezk.plain_edge_slopes(z, i, j, k, edge_ids, brk_kind, dx, dy)


def supported(model) -> bool:
    """Whether :func:`pack_model` covers every part of ``model`` (dense lattices in cell
    patches are not: the caller falls back to batched Python height calls)."""
    from ..grid import ZMap
    from ..model import PrecisionModel

    if isinstance(model, ZMap):
        return True
    if not isinstance(model, PrecisionModel):
        return False
    ez = model.ez
    if ez is None or ez.patches is None or not ez.patches.n_patches:
        return True
    p = ez.patches
    return bool(np.all(p.level > 0)) and getattr(p, "subs", None) is None


@structref.register
class _PackedModelType(types.StructRef):
    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class PackedModel(structref.StructRefProxy):
    """A model's arrays for the numba kernels (:func:`pack_model`), handed to them as one
    reference. Handed a tuple of its thirty-odd arrays instead, a kernel spent about 0.3 us of a
    base height's 0.4 us on taking it (the cost grew with the arrays in the tuple: numba counts
    references to a function's array arguments)."""


_FIELDS = ["bz", "bp", "cz_z", "cz_off", "cz_shape", "cz_par", "cell_ptr", "cell_cz", "ez_cell", "bsx", "bsy",
           "czsx", "czsy", "has_main", "E", "pcells", "PL"]
structref.define_proxy(PackedModel, _PackedModelType, _FIELDS)


@njit(cache=True)
def _copy_ez(E):
    """An EZ-map's arrays (:func:`_ez_arrays`; its fifth, the samples' ``_hq``, five arrays), copied."""
    hq = (E[4][0].copy(), E[4][1].copy(), E[4][2].copy(), E[4][3].copy(), E[4][4].copy())
    return (E[0].copy(), E[1].copy(), E[2].copy(), E[3].copy(), hq, E[5].copy(), E[6].copy(), E[7].copy(),
            E[8].copy(), E[9].copy(), E[10].copy(), E[11].copy(), E[12].copy(), E[13].copy(), E[14].copy(),
            E[15].copy())


@njit(cache=True)
def _clone(M):
    """A copy of every array of ``M``, for one thread of :func:`threaded`."""
    PL = M.PL
    pl = List()
    for k in range(len(PL)):
        pl.append(_copy_ez(PL[k]))
    return PackedModel(M.bz.copy(), M.bp.copy(), M.cz_z.copy(), M.cz_off.copy(), M.cz_shape.copy(), M.cz_par.copy(),
                       M.cell_ptr.copy(), M.cell_cz.copy(), M.ez_cell.copy(), M.bsx.copy(), M.bsy.copy(),
                       M.czsx.copy(), M.czsy.copy(), M.has_main, _copy_ez(M.E), M.pcells.copy(), pl)


def pack_model(model) -> PackedModel:
    """The arrays :func:`height_at` reads, for a PrecisionModel or a ZMap (see :func:`supported`)."""
    from ..grid import ZMap
    from ..model import _BOUNDARY_DUMMY, _TANGENT_CIRCLE, PrecisionModel

    if isinstance(model, ZMap):
        model = PrecisionModel(model)
    b = model.base
    bpar = np.array([b.x0, b.y0, b.dx, b.dy, math.cos(b.angle), math.sin(b.angle), b.origin[0], b.origin[1]],
                    dtype=np.float64)
    # the Bezier options as run-time ints: constants would be typed as literals, and the
    # slopes' kernels compiled again for them (a cold compile of seconds)
    bez = (int(_TANGENT_CIRCLE), int(_BOUNDARY_DUMMY))
    bz = np.ascontiguousarray(b.z, dtype=np.float64)
    # every node's slopes, made once: a Bezier height is then a few multiplications
    bsx, bsy = np.empty_like(bz), np.empty_like(bz)
    slope_tables(bz, b.dx, b.dy, bez[0], bez[1], bsx, bsy)
    czsx, czsy = np.empty_like(model._cz_z), np.empty_like(model._cz_z)
    for m in range(len(model._cz_shape)):
        a, e = model._cz_off[m], model._cz_off[m + 1]
        shp = (int(model._cz_shape[m, 0]), int(model._cz_shape[m, 1]))
        sx, sy = np.empty(shp), np.empty(shp)
        slope_tables(np.ascontiguousarray(model._cz_z[a:e].reshape(shp)), model._cz_par[m, 2], model._cz_par[m, 3],
                     bez[0], bez[1], sx, sy)
        czsx[a:e], czsy[a:e] = sx.ravel(), sy.ravel()
    ez = model.ez
    if ez is not None and ez.n_edges:
        main = _ez_arrays(ez, b)
        has_main = True
    else:
        from ..refine.ez import build_ez

        # an EZ-map without edges, built by its own constructor (its arrays' types are the
        # real ones); never read (has_main False)
        dummy = build_ez(b, lambda x, y: np.zeros(np.shape(x)), tol=min(b.dx, b.dy) / 4, eps_r=math.inf,
                         prune=False, verify=False, thin=False)
        main = _ez_arrays(dummy, b)
        has_main = False
    cells = np.zeros(0, dtype=np.int64)
    plist = []
    if ez is not None and ez.patches is not None and ez.patches.n_patches:
        p = ez.patches
        cells = p.cells
        for k in range(p.n_patches):
            sub, pez = p._patch_maps(k, b, ez.interval, ez.tol)
            plist.append(_ez_arrays(pez, sub))
    from numba.typed import List

    pl = List()
    for t in plist:
        pl.append(t)
    if not plist:  # a typed list needs its item type: one patch-shaped item, never indexed
        pl.append(main)
    return PackedModel(bz, bpar, model._cz_z, model._cz_off, model._cz_shape, model._cz_par, model._cell_ptr,
                       model._cell_cz, model._ez_cell, bsx, bsy, czsx, czsy, has_main, main,
                       np.ascontiguousarray(cells, dtype=np.int64), pl)


@njit(cache=True)
def _ez_at(E, x, y):
    """One EZ-map's height at world xy (its kernel's rule); NaN outside its e-cells."""
    z, par, edge_ids, offsets, hq, brk_kind, brk_t, ecell_ids, slots, nb, bk, bt, pts, arc, bub, plain = E
    nx, ny = z.shape
    i, j, u, v = _locate(x, y, par[0], par[1], par[2], par[3], par[4], par[5], par[6], par[7], nx, ny)
    if i < 0:
        return np.nan
    c = _ezk._find(ecell_ids, i * (ny - 1) + j)
    if c < 0 or math.isnan(z[i, j]) or math.isnan(z[i + 1, j]) or math.isnan(z[i, j + 1]) or math.isnan(z[i + 1, j + 1]):
        return np.nan
    if nb[c] == 2 and (pts[c, 0, 0] != pts[c, 2, 0] or pts[c, 0, 1] != pts[c, 2, 1]):
        return _ezk._split(z, i, j, u, v, c, slots, edge_ids, offsets, hq, brk_kind, brk_t, bk, bt, pts, arc,
                           par[2], par[3])
    # _ezk._coons, with the plain edges' slopes from the table
    bot = _edge_at(E, i, j, c, 0, u)
    rgt = _edge_at(E, i, j, c, 1, v)
    top = _edge_at(E, i, j, c, 2, u)
    lft = _edge_at(E, i, j, c, 3, v)
    return _ezk.coons_blend(z, i, j, u, v, bot, rgt, top, lft, nb[c] > 0, bub[c])


@njit(cache=True, inline="always")
def _edge_at(E, i, j, c, k, t):
    """:func:`zmap.refine._ez_kernels._edge_value` of e-cell c's local edge k at t (side 0),
    a plain edge from its slopes in the table (:func:`_plain_slopes`)."""
    z, par, edge_ids, offsets, hq, brk_kind, brk_t, ecell_ids, slots, nb, bk, bt, pts, arc, bub, plain = E
    slot = slots[c, k]
    if slot < 0:
        ia, ja, ib, jb = _ezk._edge_nodes(i, j, k)
        return _bezier1d(z[ia, ja], z[ib, jb], plain[c, k, 0], plain[c, k, 1], par[2] if k == 0 or k == 2 else par[3],
                         t)
    return _ezk._edge_value(z, i, j, k, t, 0, slot, edge_ids, offsets, hq, brk_kind, brk_t, par[2], par[3])


@njit(cache=True)
def height_at(M, x, y):
    """The model's height at world xy (NaN: no surface), as ``PrecisionModel.height``."""
    bz, bp = M.bz, M.bp
    nx, ny = bz.shape
    i, j, u, v = _locate(x, y, bp[0], bp[1], bp[2], bp[3], bp[4], bp[5], bp[6], bp[7], nx, ny)
    if i < 0:
        return np.nan
    cell = i * (ny - 1) + j
    # the CZ-map in which the point lies deepest (zmap._model_kernels.model_heights)
    best = deepest_cz(x, y, cell, M.cell_ptr, M.cell_cz, M.cz_par, M.cz_shape)
    if best >= 0:
        a, e = M.cz_off[best], M.cz_off[best + 1]
        shp = (M.cz_shape[best, 0], M.cz_shape[best, 1])
        cp = M.cz_par
        h = bezier_at_tabled(M.cz_z[a:e].reshape(shp), M.czsx[a:e].reshape(shp), M.czsy[a:e].reshape(shp),
                             cp[best, 0], cp[best, 1], cp[best, 2], cp[best, 3], cp[best, 4], cp[best, 5],
                             cp[best, 6], cp[best, 7], x, y)
        if h == h:
            return h
    if not M.ez_cell[cell]:
        return bezier_at_tabled(bz, M.bsx, M.bsy, bp[0], bp[1], bp[2], bp[3], bp[4], bp[5], bp[6], bp[7], x, y)
    he = np.nan
    if M.has_main:
        he = _ez_at(M.E, x, y)
    pcells = M.pcells
    if pcells.shape[0]:
        # the patched cell, by the local coordinates as CellPatches.evaluate finds it
        lx, ly = _to_local(x, y, bp[4], bp[5], bp[6], bp[7])
        pi = int(math.floor((lx - bp[0]) / bp[2]))
        pj = int(math.floor((ly - bp[1]) / bp[3]))
        if pi == nx - 1:
            pi = nx - 2
        if pj == ny - 1:
            pj = ny - 2
        if 0 <= pi <= nx - 2 and 0 <= pj <= ny - 2:
            k = _ezk._find(pcells, pi * (ny - 1) + pj)
            if k >= 0:
                hp = _ez_at(M.PL[k], x, y)
                if hp == hp:
                    he = hp
    if he == he:
        return he
    # the base's surface where the EZ-map gives none (made only then)
    return bezier_at_tabled(bz, M.bsx, M.bsy, bp[0], bp[1], bp[2], bp[3], bp[4], bp[5], bp[6], bp[7], x, y)


@njit(cache=True, nogil=True)
def heights(M, xs, ys, out, k0, k1):
    """:func:`height_at` at points ``k0:k1`` (no GIL held: callers thread over chunks, since
    numba's parallel loops do not take the tuple of arrays a model is)."""
    for k in range(k0, k1):
        out[k] = height_at(M, xs[k], ys[k])
