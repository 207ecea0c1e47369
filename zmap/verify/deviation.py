"""Stock against design: deviation per ray, gouge / within / excess, regions, first offending line.

Per ray of the simulated stock, ``deviation = stock top - (design height + offset)``; the ray
is *within* in ``[-tol, tol]``, *excess* above ``tol`` and below ``-tol`` a *gouge* where the
program cut it (the classification of 3DEXPERIENCE's and Vericut's stock-to-design
comparisons; ``offset`` is a stock allowance left on purpose). A gouge is material the program
removed: a ray below ``-tol`` that no cut has touched (its top is the stock's top at stage 0)
was short before the program began, because stock and design were sampled differently (the
stock interpolated from a map across a wall or a rim, say) or the stock is too small. Such a
ray is *outline* when it lies along the part's outline (next to a ray where stock and design
are not both defined), *short* elsewhere. A ray where only one of stock and design has a
height inside the design's extent (its map's bounds, the part's box; next to a compared ray
for a design given as a function) is *outline* too: the part's outline sampled differently
by the two, or stock beside the part. Outside the design's extent a ray is *uncovered*.
Neither outline nor short is ever a gouge.

Connected gouge and excess rays (8-neighbours) form regions with area, volume, depth and
bounding box, largest volume first. For every gouge ray the history tells the first stage at
which the program cut it below ``design + offset - tol`` (:func:`first_offending`), and the
run's ``line`` array the G-code line of that stage, with no re-simulation: a first line is
always a line of the program (stage >= 1), never the stock as it stood at stage 0.
"""

from __future__ import annotations

import math
import os
import time
import warnings
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np


__all__ = ["compare", "Comparison", "Region", "design_heights", "first_offending", "CLASSES",
           "load_design"]

#: class codes of :attr:`Comparison.classes` (see the module's description)
CLASSES = {"uncovered": 0, "gouge": 1, "within": 2, "excess": 3, "outline": 4, "short": 5}
_MM_PER_INCH = 25.4


@dataclass
class Region:
    """One connected gouge or excess region.

    Attributes
    ----------
    kind : {"gouge", "excess"}
    rays : int
        Rays in the region.
    area : float
        mm^2 (rays x pitch^2).
    volume : float
        mm^3: material missing below ``design + offset`` (gouge) or left above it (excess), summed
        over the region's rays.
    depth : float
        mm, the largest ``|deviation|`` in the region.
    bbox : (xmin, ymin, xmax, ymax)
        mm, ray centres.
    deepest : (x, y)
        mm, the ray of the largest ``|deviation|``.
    first_stage, first_line : int
        Gouges: the earliest stage (>= 1) at which the program cut a ray of the region below
        ``design + offset - tol``, and its G-code line (>= 1); -1 when unknown (a run of bare
        positions has no lines).
    first_xy : (x, y)
        mm, the ray that went first (NaN when unknown).
    """

    kind: str
    rays: int
    area: float
    volume: float
    depth: float
    bbox: tuple
    deepest: tuple
    first_stage: int = -1
    first_line: int = -1
    first_xy: tuple = (math.nan, math.nan)

    def as_dict(self) -> dict:
        return {"kind": self.kind, "rays": self.rays, "area_mm2": self.area, "volume_mm3": self.volume,
                "depth_mm": self.depth, "xmin": self.bbox[0], "ymin": self.bbox[1], "xmax": self.bbox[2],
                "ymax": self.bbox[3], "deepest_x": self.deepest[0], "deepest_y": self.deepest[1],
                "first_stage": self.first_stage, "first_line": self.first_line,
                "first_x": self.first_xy[0], "first_y": self.first_xy[1]}


@dataclass
class Comparison:
    """Result of :func:`compare`.

    Attributes
    ----------
    x0, y0, pitch : float
        Ray grid, mm; ray (i, j) at ``(x0 + i*pitch, y0 + j*pitch)``.
    stage, n_stages : int
        The stage compared and the run's last stage.
    tol, offset : float
        mm.
    top : ndarray of shape (nx, ny), float64
        Stock top at ``stage`` (an emptied ray takes its stock bottom; NaN where the stock never had
        material).
    design : ndarray of shape (nx, ny), float64
        Design heights (NaN: not covered).
    deviation : ndarray of shape (nx, ny), float64
        ``top - (design + offset)``, NaN where uncovered.
    classes : ndarray of shape (nx, ny), int8
        :data:`CLASSES` codes.
    first_stage, first_line : ndarray of shape (nx, ny), int32
        Per gouge ray, the first stage (>= 1) at which the program cut it below
        ``design + offset - tol``, and its G-code line (>= 1, -1 when the run has no lines); -1
        elsewhere.
    regions : list of Region
        Gouges and excesses, each kind by volume, largest first.
    totals : dict
        Figures of the whole comparison (never NaN): rays, area (and for gouges and excesses volume)
        of each class, ``outline_rays``/``outline_area_mm2`` and ``short_rays``/``short_area_mm2``
        among them; ``first_gouge_stage`` and ``first_gouge_line`` when a gouge has a known line of
        the program.
    """

    x0: float
    y0: float
    pitch: float
    stage: int
    n_stages: int
    tol: float
    offset: float
    top: np.ndarray
    design: np.ndarray
    deviation: np.ndarray
    classes: np.ndarray
    first_stage: np.ndarray
    first_line: np.ndarray
    regions: list
    totals: dict
    seconds: dict = field(default_factory=dict)

    @property
    def gouges(self) -> list:
        return [r for r in self.regions if r.kind == "gouge"]

    @property
    def excesses(self) -> list:
        return [r for r in self.regions if r.kind == "excess"]

    def first_gouge(self) -> Region | None:
        """The gouge region cut first (smallest first stage), or None."""
        g = [r for r in self.gouges if r.first_stage >= 0]
        return min(g, key=lambda r: r.first_stage) if g else None


# ---- design --------------------------------------------------------------------------------

def load_design(design: Any) -> Any:
    """A design model from a path (``.zpm``, ``.zmap.npz``, ``.step``/``.stp``: see
    :func:`zmap.design.read_design`) or as given."""
    if not isinstance(design, (str, os.PathLike)):
        return design
    from ..design import read_design

    return read_design(design)


def design_heights(design: Any) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """``heights(x, y)`` of a design: PrecisionModel, ZMap or TiledZMap (Bezier), STEP part (exact) or callable
    (:func:`zmap.design.as_design`)."""
    from ..design import as_design

    return as_design(design).heights


def _overlap(a: tuple, b: tuple) -> float:
    """Fraction of box ``a`` (xmin, ymin, xmax, ymax) that box ``b`` covers."""
    w = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    h = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    area = max((a[2] - a[0]) * (a[3] - a[1]), 1e-300)
    return w * h / area


def _check_units(stock_box: tuple, design_box: tuple | None, where: str) -> None:
    """Refuse a design whose extent fits the stock only once scaled by 25.4 (inch vs mm)."""
    if design_box is None:
        return
    here = _overlap(stock_box, design_box)
    if here >= 0.5:
        return
    for f, what in ((_MM_PER_INCH, "inches"), (1 / _MM_PER_INCH, "mm while the stock is in inches")):
        scaled = tuple(v * f for v in design_box)
        if _overlap(stock_box, scaled) >= 0.5 and _overlap(scaled, stock_box) >= 0.25:
            raise ValueError(
                f"design {where} spans x {design_box[0]:.4g}..{design_box[2]:.4g}, y {design_box[1]:.4g}.."
                f"{design_box[3]:.4g} but the stock x {stock_box[0]:.4g}..{stock_box[2]:.4g}, y "
                f"{stock_box[1]:.4g}..{stock_box[3]:.4g} mm: the design looks to be in {what} "
                f"(scaled by {f:.4g} it covers the stock); convert it to mm")


# ---- history ---------------------------------------------------------------------------------

def first_offending(run: Any, rays: np.ndarray, level: np.ndarray, *, floor: np.ndarray | None = None) -> np.ndarray:
    """First stage at which each ray's top went below ``level``, read from the run's history.

    Parameters
    ----------
    run : zmap.sim.session.Run
        With ``history="treap"`` (others: bisection over stages on :meth:`Run.display`, slower;
        ``"none"`` replays).
    rays : ndarray of shape (m,), int
        Flat ray ids ``i*ny + j``.
    level : ndarray of shape (m,), float64
        mm.
    floor : ndarray of shape (m,), optional
        Height taken for a ray left without material (default -inf: an emptied ray is below any
        level).

    Returns
    -------
    ndarray of shape (m,), int32 — the stage, or -1 where the top never went below.

    Examples
    --------
    >>> import numpy as np
    >>> from zmap.sim import simulate
    >>> run = simulate(np.array([[1.0, 1.0, -0.2], [1.0, 1.0, -0.8]]), (0, 0, -2, 2, 2, 0),
    ...                tool="flat:1", pitch=0.5)
    >>> ray = 2 * run.stock.ny + 2
    >>> first_offending(run, np.array([ray]), np.array([-0.5])).tolist()
    [2]
    """
    rays = np.ascontiguousarray(rays, dtype=np.int64).ravel()
    level = np.ascontiguousarray(np.broadcast_to(np.asarray(level, dtype=np.float64), rays.shape))
    floor = (np.full(rays.shape, -np.inf) if floor is None
             else np.ascontiguousarray(np.broadcast_to(np.asarray(floor, dtype=np.float64), rays.shape)))
    out = np.full(rays.shape, -1, dtype=np.int32)
    if rays.size == 0:
        return out
    st = run.structure
    if run.history == "treap":
        from . import _verify_kernels as K

        sizes = np.diff(st.node_off)
        m = int(sizes.max()) + 2 if sizes.size else 2
        K.treap_first_below(st.node_off, st.root_off, st.root_hi, st.z, st.stage, st.kids, rays, level, floor,
                            out, np.empty(m, dtype=np.int64), np.empty(m, dtype=np.float32),
                            np.empty(m, dtype=np.float32), np.empty(m, dtype=np.int32))
        return out
    # other histories: bisection over stages, one full display per step
    def tops(k: int) -> np.ndarray:
        t = run.display(k).ravel()[rays]
        return np.where(np.isnan(t), floor, t)

    below_end = tops(run.n_stages) < level
    below0 = tops(0) < level
    lo = np.where(below0, 0, 1)
    hi = np.full(rays.shape, run.n_stages)
    active = below_end & ~below0
    while True:
        act = active & (lo < hi)
        if not act.any():
            break
        mid = (lo + hi) // 2
        for k in np.unique(mid[act]):
            sel = act & (mid == k)
            b = tops(int(k))[sel] < level[sel]
            idx = np.flatnonzero(sel)
            hi[idx[b]] = k
            lo[idx[~b]] = k + 1
    out[below_end] = lo[below_end]
    return out


# ---- compare ---------------------------------------------------------------------------------

def _check_tol(tol: Any, offset: Any) -> tuple[float, float]:
    try:
        t = float(tol)
        o = float(offset)
    except (TypeError, ValueError):
        raise ValueError(f"tol and offset must be numbers of mm, got tol={tol!r}, offset={offset!r}") from None
    if not (math.isfinite(t) and t >= 0):
        raise ValueError(f"tol must be a finite number of mm >= 0, got {tol!r}")
    if not math.isfinite(o):
        raise ValueError(f"offset must be a finite number of mm, got {offset!r}")
    return t, o


def _classify(covered: np.ndarray, dev: np.ndarray, tol: float, has_design: np.ndarray, has_stock: np.ndarray,
              cut: np.ndarray, inside: np.ndarray | None = None) -> np.ndarray:
    """:data:`CLASSES` code of each ray (see the module's description).

    Parameters
    ----------
    covered : ndarray of shape (nx, ny), bool
        Stock and design both have a height.
    dev : ndarray of shape (nx, ny), float64
        Deviation, mm (NaN where not covered).
    tol : float
        mm.
    has_design, has_stock : ndarray of shape (nx, ny), bool
        The design has a height; the stock has (or had, at stage 0) material.
    cut : ndarray of shape (nx, ny), bool
        The program has lowered the ray's top.
    inside : ndarray of shape (nx, ny), bool, optional
        Rays inside the design's extent (default: the compared rays and their 8 neighbours).

    Examples
    --------
    >>> import numpy as np
    >>> cov = np.array([[True, True, True, False]])
    >>> dev = np.array([[-0.5, -0.5, -0.5, np.nan]])
    >>> _classify(cov, dev, 0.01, cov, np.ones((1, 4), bool), np.array([[True, False, False, False]])).tolist()
    [[1, 5, 4, 4]]
    """
    from scipy import ndimage

    eight = np.ones((3, 3), bool)
    one_sided = has_design ^ has_stock
    classes = np.zeros(covered.shape, dtype=np.int8)
    with np.errstate(invalid="ignore"):
        below = covered & (dev < -tol)
        classes[covered & (dev >= -tol) & (dev <= tol)] = CLASSES["within"]
        classes[covered & (dev > tol)] = CLASSES["excess"]
    classes[below & cut] = CLASSES["gouge"]
    # never cut, yet below: the stock began short of the design (sampled differently)
    edge = ndimage.binary_dilation(~covered, structure=eight) & covered
    classes[below & ~cut] = np.where(edge[below & ~cut], CLASSES["outline"], CLASSES["short"])
    # one of stock and design without a height within the design's extent: the part's outline
    if inside is None:
        inside = ndimage.binary_dilation(covered, structure=eight)
    classes[one_sided & (inside | has_design)] = CLASSES["outline"]
    return classes


def compare(run: Any, design: Any, *, stage: Any = "end", tol: float = 0.01, offset: float = 0.0,
            connectivity: int = 8, first: bool = True) -> Comparison:
    """Compare a simulated stock at ``stage`` with a design surface.

    Parameters
    ----------
    run : zmap.sim.session.Run or path of a ``.zsim`` file
    design : PrecisionModel, ZMap, cad_io Part, heights(x, y) callable, or a path
        (``.zpm``, ``.zmap.npz``, ``.step``/``.stp``) — the design heights in mm.
    stage : int, "end" or a fraction text like "1/2"
    tol : float
        Half-width of the tolerance band, mm (>= 0).
    offset : float
        Design offset (stock allowance), mm: the target is ``design + offset``.
    connectivity : {4, 8}
        Neighbours that join rays into regions.
    first : bool
        Find the first offending stage and line of every gouge ray.

    Returns
    -------
    Comparison

    Warns
    -----
    UserWarning
        Where the design does not cover every ray of the stock (the uncovered area is in
        ``totals["uncovered_area_mm2"]``), or no ray is covered at all.

    Examples
    --------
    >>> import numpy as np
    >>> from zmap import ZMap
    >>> from zmap.sim import simulate
    >>> run = simulate(np.array([[2.0, 2.0, -0.5]]), (0, 0, -2, 4, 4, 0), tool="flat:1", pitch=0.25)
    >>> flat = ZMap.from_function(lambda x, y: 0 * x - 0.2, (-1, -1, 5, 5), 0.5)
    >>> c = compare(run, flat, tol=0.01)
    >>> c.totals["gouge_regions"], c.gouges[0].first_stage
    (1, 1)
    """
    from scipy import ndimage

    from ..sim.session import Run

    t0 = time.perf_counter()
    tol, offset = _check_tol(tol, offset)
    if connectivity not in (4, 8):
        raise ValueError(f"connectivity={connectivity!r} is not one of 4, 8")
    if isinstance(run, (str, os.PathLike)):
        run = Run.load(run)
    where = str(design) if isinstance(design, (str, os.PathLike)) else type(design).__name__
    from ..design import as_design

    design_of = as_design(load_design(design))
    heights = design_of.heights
    k = run.stage(stage)
    s = run.stock
    nx, ny, p = s.nx, s.ny, float(s.pitch)
    stock_box = (s.x0, s.y0, s.x0 + (nx - 1) * p, s.y0 + (ny - 1) * p)
    _check_units(stock_box, design_of.bounds, where)

    t1 = time.perf_counter()
    top = np.asarray(run.display(k), dtype=np.float64).reshape(nx, ny)
    bottom = s.to_csr()
    off, near = bottom[0], bottom[1]
    had = np.diff(off) > 0
    floor = np.full(nx * ny, np.nan)
    floor[had] = near[off[:-1][had]]  # stock bottom of each ray (its first dexel's NaerZ)
    floor = floor.reshape(nx, ny)
    top = np.where(np.isnan(top), floor, top)
    # the stock before the program: a ray whose top is still this was never cut
    top0 = top if k == 0 else np.asarray(run.display(0), dtype=np.float64).reshape(nx, ny)
    top0 = np.where(np.isnan(top0), floor, top0)
    X, Y = np.meshgrid(s.x, s.y, indexing="ij")
    t2 = time.perf_counter()
    dz = np.asarray(heights(X.ravel(), Y.ravel()), dtype=np.float64).reshape(nx, ny)
    t3 = time.perf_counter()

    covered = np.isfinite(dz) & np.isfinite(top)
    dev = np.where(covered, top - (dz + offset), np.nan)
    box = design_of.bounds
    inside = None
    if box is not None:
        eps = 1e-9 * max(1.0, *map(abs, box))
        inside = (X >= box[0] - eps) & (X <= box[2] + eps) & (Y >= box[1] - eps) & (Y <= box[3] + eps)
    classes = _classify(covered, dev, tol, np.isfinite(dz), np.isfinite(top), top < top0, inside)
    cell = p * p
    n_cov = int(covered.sum())
    unc = nx * ny - n_cov
    if n_cov == 0:
        warnings.warn(f"design {where} covers none of the stock's {nx * ny} rays: nothing to compare",
                      UserWarning, stacklevel=2)
    elif unc:
        n_edge = int((~covered & (classes == CLASSES["outline"])).sum())
        warnings.warn(f"design {where} does not cover {unc} of {nx * ny} stock rays "
                      f"({unc * cell:.4g} mm^2; {n_edge} of them inside its extent, along the part's outline); "
                      f"they are left out of the comparison", UserWarning, stacklevel=2)

    # first offending stage per gouge ray, from the history
    first_stage = np.full((nx, ny), -1, dtype=np.int32)
    first_line = np.full((nx, ny), -1, dtype=np.int32)
    gmask = classes == CLASSES["gouge"]
    t4 = time.perf_counter()
    if first and gmask.any():
        rays = np.flatnonzero(gmask.ravel())
        # below the target and below the stock's first top: the program's cut (stage >= 1),
        # also where the stock began below the target
        lev = np.minimum(dz + offset - tol, top0).ravel()[rays]
        fl = np.where(np.isnan(floor), -np.inf, floor).ravel()[rays]
        fs = first_offending(run, rays, lev, floor=fl)
        first_stage.ravel()[rays] = fs
        ok = fs > 0
        lines = np.full(fs.shape, -1, dtype=np.int32)
        lines[ok] = run.line[fs[ok] - 1]
        first_line.ravel()[rays] = np.where(lines > 0, lines, -1)
    t5 = time.perf_counter()

    structure = np.ones((3, 3), bool) if connectivity == 8 else None
    regions: list[Region] = []
    for kind in ("gouge", "excess"):
        mask = classes == CLASSES[kind]
        lab, n = ndimage.label(mask, structure=structure)
        if n == 0:
            continue
        idx = lab.ravel()
        sel = idx > 0
        li = idx[sel] - 1
        a = np.abs(dev.ravel()[sel])
        counts = np.bincount(li, minlength=n)
        vol = np.bincount(li, weights=a, minlength=n) * cell
        depth = np.zeros(n)
        np.maximum.at(depth, li, a)
        flat_ids = np.flatnonzero(sel)
        order = np.lexsort((-a, li))  # per label, deepest first
        first_of = np.searchsorted(li[order], np.arange(n))
        deepest = flat_ids[order[first_of]]
        fs_all = first_stage.ravel()[sel]
        objs = ndimage.find_objects(lab)
        for q in range(n):
            sl = objs[q]
            i0, i1, j0, j1 = sl[0].start, sl[0].stop - 1, sl[1].start, sl[1].stop - 1
            di, dj = divmod(int(deepest[q]), ny)
            reg = Region(kind, int(counts[q]), float(counts[q] * cell), float(vol[q]), float(depth[q]),
                         (s.x0 + i0 * p, s.y0 + j0 * p, s.x0 + i1 * p, s.y0 + j1 * p),
                         (s.x0 + di * p, s.y0 + dj * p))
            if kind == "gouge":
                mine = (li == q) & (fs_all > 0)
                if mine.any():
                    cand = np.flatnonzero(mine)
                    w = cand[np.argmin(fs_all[cand])]
                    fi, fj = divmod(int(flat_ids[w]), ny)
                    reg.first_stage = int(fs_all[w])
                    reg.first_line = int(first_line[fi, fj])
                    reg.first_xy = (s.x0 + fi * p, s.y0 + fj * p)
            regions.append(reg)
    regions.sort(key=lambda r: (r.kind != "gouge", -r.volume))
    t6 = time.perf_counter()

    g = classes == CLASSES["gouge"]
    e = classes == CLASSES["excess"]
    w = classes == CLASSES["within"]
    n_unc = int((classes == CLASSES["uncovered"]).sum())
    n_out = int((classes == CLASSES["outline"]).sum())
    n_short = int((classes == CLASSES["short"]).sum())
    totals = {
        "stage": k, "n_stages": run.n_stages, "tol_mm": tol, "offset_mm": offset, "pitch_mm": p,
        "rays": nx * ny, "covered_rays": n_cov, "uncovered_rays": n_unc, "uncovered_area_mm2": n_unc * cell,
        "outline_rays": n_out, "outline_area_mm2": n_out * cell, "short_rays": n_short,
        "short_area_mm2": n_short * cell,
        "gouge_rays": int(g.sum()), "within_rays": int(w.sum()), "excess_rays": int(e.sum()),
        "gouge_area_mm2": float(g.sum() * cell), "excess_area_mm2": float(e.sum() * cell),
        "gouge_volume_mm3": float(np.abs(dev[g]).sum() * cell), "excess_volume_mm3": float(dev[e].sum() * cell),
        "max_gouge_mm": float(-dev[g].min()) if g.any() else 0.0,
        "max_excess_mm": float(dev[e].max()) if e.any() else 0.0,
        "min_deviation_mm": float(dev[covered].min()) if n_cov else 0.0,
        "max_deviation_mm": float(dev[covered].max()) if n_cov else 0.0,
        "gouge_regions": sum(r.kind == "gouge" for r in regions),
        "excess_regions": sum(r.kind == "excess" for r in regions),
    }
    fg = [r for r in regions if r.kind == "gouge" and r.first_stage > 0]
    if fg:
        r0 = min(fg, key=lambda r: r.first_stage)
        totals["first_gouge_stage"] = r0.first_stage
        if r0.first_line > 0:  # a line of the program (a run of bare positions has none)
            totals["first_gouge_line"] = r0.first_line
    seconds = {"load": t1 - t0, "stock": t2 - t1, "design": t3 - t2, "classify": t4 - t3,
               "first": t5 - t4, "regions": t6 - t5, "total": t6 - t0}
    return Comparison(s.x0, s.y0, p, k, run.n_stages, tol, offset, top, dz, dev, classes, first_stage,
                      first_line, regions, totals, seconds)
