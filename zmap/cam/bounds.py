"""Certified drop-cutter: the design as Bezier patches with bounds, split until the answer is sure.

:class:`BoundingSurface` holds a design as a grid of bicubic Bezier patches (control nets),
their exact nodes and, per cell, a margin by which the design may rise above its patch.
:func:`drop_bound` drops a cutter onto it by branch and bound (:mod:`zmap.cam._bound_kernels`):
a lower bound from exact points of the design, an upper bound per cell from its control net
minus the tangent plane of the cutter's envelope, cells split until no bound beats the lower
one by more than ``eps``. The answer is the largest bound left: never below the design's true
cutter-location height (a program made from it does not gouge), and never above it by more
than ``eps`` where the cells are exact.

Where the surface comes from:

* a :class:`~zmap.ZMap`: its own Bezier surface (:func:`zmap.interpolate.bezier`), exactly:
  every cell's net is the patch, margin 0. The answer is certified.
* any other design (a :class:`~zmap.model.PrecisionModel`, a STEP part's exact heights, a
  callable): :func:`from_heights` samples it on a grid (the nodes are exact design heights)
  and on a grid ``check`` times finer; the margin of a cell is the largest distance of the
  design's samples inside it from the patch through its nodes, either side, times
  :data:`MARGIN_FACTOR` (a bend the cubic does not follow errs both ways between samples). A
  cell with a wall or a step inside or beside it (two neighbouring samples differ by more than
  :data:`WALL` times their spacing) where the samples stray from the patch by more than
  :data:`ROUGH`, or one whose samples stray far, is bounded by flat sub-cells, one per fine
  spacing, each at its highest corner sample plus how far a crest between its samples can rise
  (the secants beyond each side, extended inward, cross no higher): the safe side of a step,
  high by what moving the wall one fine spacing toward the cutter gives.
  Cells with part of the design missing (the outline) are bounded the same way by the samples
  they have. The answer is then as sure as the samples: a feature narrower than the fine
  grid's spacing between two samples can still be under-rated.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from ..gridspec import lines_covering

__all__ = ["BoundingSurface", "from_zmap", "from_heights", "from_samples", "drop_bound", "MARGIN_FACTOR", "ROUGH"]

#: a sampled cell's margin is its samples' largest distance from the patch (either side) times this
MARGIN_FACTOR = 1.5
#: mm: a sampled cell whose samples stray further from its patch is a flat patch (a step, a wall)
ROUGH = 5e-4
#: mm: margins below this count as 0 (exact cells); the drop's answer can then be below the
#: sampled design by this at most
TINY = 1e-5
#: a rise steeper than this between two neighbouring samples is a wall, not a slope
WALL = 10.0
#: cells per side of a block of the pruning pyramid
_B = 8
#: mm: the default certainty of the answer
EPS = 1e-5


@dataclass
class BoundingSurface:
    """A design as Bezier patches with bounds (see the module docstring).

    Attributes
    ----------
    nets : ndarray (ncx, ncy, 4, 4)
        Each cell's control net, NaN where the cell has no patch.
    cmax : ndarray (ncx, ncy)
        Each net's highest control point (-inf: no patch).
    margin : ndarray (ncx, ncy)
        mm the design may rise above the patch (0: exact).
    z : ndarray (nx, ny)
        The nodes, exact heights of the design (NaN: none).
    x0, y0, dx, dy : float
        The node grid, mm.
    source : str
        What the surface was made from.
    sub, subidx : ndarray
        Flat cells as finer flat sub-cells: ``sub[subidx[ci, cj]]`` their heights (n x n, NaN:
        none); ``subidx`` -1 for a patch.
    """

    nets: np.ndarray
    cmax: np.ndarray
    margin: np.ndarray
    z: np.ndarray
    x0: float
    y0: float
    dx: float
    dy: float
    source: str
    sub: np.ndarray = None
    subidx: np.ndarray = None

    def __post_init__(self) -> None:
        from ._drop_kernels import block_max

        if self.sub is None:
            self.sub = np.zeros((0, 1, 1))
            self.subidx = np.full(self.cmax.shape, -1, dtype=np.int64)
        top = np.where(np.isfinite(self.cmax), self.cmax + self.margin, -np.inf)
        self.bcell = np.empty(((top.shape[0] + _B - 1) // _B, (top.shape[1] + _B - 1) // _B))
        block_max(np.ascontiguousarray(top), _B, self.bcell)
        self.bnode = np.empty(((self.z.shape[0] + _B - 1) // _B, (self.z.shape[1] + _B - 1) // _B))
        block_max(self.z, _B, self.bnode)

    @property
    def exact(self) -> bool:
        """True where every cell is the design itself (a z-map's own surface)."""
        return bool(not np.any(self.margin > 0))

    def covers(self, lo_x: float, lo_y: float, hi_x: float, hi_y: float) -> bool:
        """Whether the node grid covers the rectangle."""
        nx, ny = self.z.shape
        return (self.x0 <= lo_x + 1e-9 and self.y0 <= lo_y + 1e-9 and self.x0 + (nx - 1) * self.dx >= hi_x - 1e-9
                and self.y0 + (ny - 1) * self.dy >= hi_y - 1e-9)


def _nets_of(z: np.ndarray, dx: float, dy: float) -> tuple[np.ndarray, np.ndarray]:
    from .._interp_kernels import BOUNDARY_DUMMY, TANGENT_CIRCLE, slope_tables
    from . import _bound_kernels as BK

    z = np.ascontiguousarray(z, dtype=np.float64)
    sx = np.empty_like(z)
    sy = np.empty_like(z)
    slope_tables(z, dx, dy, TANGENT_CIRCLE, BOUNDARY_DUMMY, sx, sy)
    nx, ny = z.shape
    nets = np.empty((max(nx - 1, 0), max(ny - 1, 0), 4, 4))
    cmax = np.empty(nets.shape[:2])
    BK.cell_nets(z, sx, sy, dx, dy, nets, cmax)
    return nets, cmax


def from_zmap(zm: Any) -> BoundingSurface:
    """A z-map's own Bezier surface (:func:`zmap.interpolate.bezier`, circle tangents, dummy
    boundary), exactly: margin 0 everywhere."""
    if zm.has_frame:
        raise ValueError("the drop-cutter takes z-maps without a local frame")
    z = np.ascontiguousarray(zm.z, dtype=np.float64)
    nets, cmax = _nets_of(z, zm.dx, zm.dy)
    return BoundingSurface(nets, cmax, np.zeros(cmax.shape), z, float(zm.x0), float(zm.y0), float(zm.dx),
                           float(zm.dy), "z-map")


def from_heights(heights: Callable, bounds: tuple, pitch: float, *, check: int = 4,
                 source: str = "sampled heights") -> BoundingSurface:
    """A design known by its heights, sampled: nodes every ``pitch`` over ``bounds``
    ``(xmin, ymin, xmax, ymax)``, margins from a grid ``check`` times finer.

    Parameters
    ----------
    heights : callable ``heights(x, y)``
        The design's heights, mm, NaN where it has none.
    bounds : (xmin, ymin, xmax, ymax)
        The region, mm (the grid covers it).
    pitch : float
        Node spacing, mm.
    check : int
        Fine samples per node interval (>= 2).

    Examples
    --------
    >>> import numpy as np
    >>> bs = from_heights(lambda x, y: 0.1 * x * y, (0, 0, 2, 2), 0.5)
    >>> bs.z.shape, float(bs.margin.max()) < 1e-12
    ((5, 5), True)
    """
    check = int(check)
    if check < 2:
        raise ValueError(f"check must be at least 2, got {check}")
    x0, y0, x1, y1 = (float(v) for v in bounds)
    nx = lines_covering(x0, x1, pitch, at_least=1)
    ny = lines_covering(y0, y1, pitch, at_least=1)
    h = pitch / check
    X, Y = np.meshgrid(x0 + h * np.arange((nx - 1) * check + 1), y0 + h * np.arange((ny - 1) * check + 1),
                       indexing="ij")
    F = np.asarray(heights(X.ravel(), Y.ravel()), dtype=np.float64).reshape(X.shape)
    return from_samples(F, x0, y0, pitch, check, source=source)


def from_samples(F: np.ndarray, x0: float, y0: float, pitch: float, check: int, *,
                 source: str = "sampled heights") -> BoundingSurface:
    """:func:`from_heights` from the fine samples themselves: ``F[a, b]`` is the design's height
    at ``(x0 + a * pitch / check, y0 + b * pitch / check)``; its shape is
    ``((nx - 1) * check + 1, (ny - 1) * check + 1)``."""
    from . import _bound_kernels as BK

    check = int(check)
    F = np.asarray(F, dtype=np.float64)
    if F.ndim != 2 or (F.shape[0] - 1) % check or (F.shape[1] - 1) % check or min(F.shape) < check + 1:
        raise ValueError(f"samples of shape {F.shape} are not (n - 1) * {check} + 1 on each side")
    h = pitch / check
    fx = x0 + h * np.arange(F.shape[0])
    fy = y0 + h * np.arange(F.shape[1])
    z = np.ascontiguousarray(F[::check, ::check])
    nets, cmax = _nets_of(z, pitch, pitch)
    # the patch at every fine sample, and each cell's largest rise of the samples above it
    P = np.empty(F.size)
    XX, YY = np.meshgrid(fx, fy, indexing="ij")
    BK.patch_heights(nets, x0, y0, pitch, pitch, np.ascontiguousarray(XX.ravel()), np.ascontiguousarray(YY.ravel()),
                     P)
    del XX, YY
    P = P.reshape(F.shape)
    ncx, ncy = cmax.shape
    rise = np.full((ncx, ncy), -np.inf)
    dev = np.zeros((ncx, ncy))
    smax = np.full((ncx, ncy), -np.inf)
    with np.errstate(invalid="ignore"):
        D = F - P
        for a in range(check + 1):
            for b in range(check + 1):
                f = F[a:a + ncx * check:check, b:b + ncy * check:check][:ncx, :ncy]
                d = D[a:a + ncx * check:check, b:b + ncy * check:check][:ncx, :ncy]
                np.fmax(rise, d, out=rise)
                np.fmax(dev, np.abs(d), out=dev)
                np.fmax(smax, f, out=smax)
    full = np.isfinite(cmax)
    # the design can rise above its patch between two samples where the samples lie below it
    # too (a bend the cubic does not follow swings the error both ways): the margin takes
    # the samples' largest distance from the patch either side
    margin = np.where(full, np.maximum(np.nan_to_num(rise, neginf=0.0), dev) * MARGIN_FACTOR, 0.0)
    # a rise this small is rounding (the samples and the patch agree): the cell counts as exact
    margin[margin < TINY] = 0.0
    # a step or a wall between the nodes (a jump between two samples and the patch through the
    # nodes strays from them, or it strays far, or its control net is far above them), or a
    # cell on the outline: bounded by flat sub-cells (below), the safe side of a step
    with np.errstate(invalid="ignore"):
        # a jump between two neighbouring samples steeper than WALL: a wall or a step inside
        jump = np.zeros((ncx, ncy), dtype=bool)
        for Dd, (ax, bx) in ((np.abs(np.diff(F, axis=0)), (check, check + 1)),
                             (np.abs(np.diff(F, axis=1)), (check + 1, check))):
            for a in range(ax):
                for b in range(bx):
                    jump |= Dd[a:a + ncx * check:check, b:b + ncy * check:check][:ncx, :ncy] > WALL * h
        # and the cells beside it (the node slopes across a step bend their patches too)
        near = jump.copy()
        near[1:, :] |= jump[:-1, :]
        near[:-1, :] |= jump[1:, :]
        near[:, 1:] |= near[:, :-1].copy()
        near[:, :-1] |= near[:, 1:].copy()
        flat = ((full & ((near & (dev > ROUGH)) | (dev > 100 * ROUGH) | (cmax - smax > 10 * ROUGH)))
                | (~full & np.isfinite(smax)))
    # each fine sub-cell of a flat cell is flat at the highest of its corners raised by how far
    # a ridge between them can rise (a ramp up to a wall's top edge, a crest between samples)
    fi, fj = np.nonzero(flat)
    subidx = np.full((ncx, ncy), -1, dtype=np.int64)
    subidx[fi, fj] = np.arange(fi.size)
    sub = _sub_cells(F, h, fi, fj, check)
    margin[flat] = 1e-9
    if fi.size:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            nets[flat] = np.nanmax(sub.reshape(fi.size, check * check), axis=1)[:, None, None]
    BK.cell_max(nets, cmax)
    return BoundingSurface(np.ascontiguousarray(nets), cmax, np.ascontiguousarray(margin), z, x0, y0, float(pitch),
                           float(pitch), source, sub, subidx)


def _ridge_excess(fa: np.ndarray, fb: np.ndarray, sa: np.ndarray, sb: np.ndarray, wall: float) -> np.ndarray:
    """How far a design can rise between two neighbouring samples ``fa``, ``fb`` above the
    higher of them, from the rises ``sa`` (into the segment at a, from the sample before a)
    and ``sb`` (at b, from the sample after b): a ridge between them lies under both lines
    extended from outside (a concave stretch lies under its secants), so its top is at most
    where they cross. Where one side's line is missing (a wall, a steeper rise than ``wall``,
    or no sample) the other line alone is extended across the whole segment; where the
    segment itself is a wall, the line of its top side is."""
    top = np.fmax(fa, fb)
    with np.errstate(invalid="ignore", divide="ignore"):
        jump = np.abs(fb - fa) > wall
        ok_a = np.isfinite(sa) & (np.abs(sa) <= wall) & ~(jump & (fa < fb))
        ok_b = np.isfinite(sb) & (np.abs(sb) <= wall) & ~(jump & (fb < fa))
        both = ok_a & ok_b & (sa > 0) & (sb > 0)
        t = np.where(both, (fb + sb - fa) / (sa + sb), 0.0)
        cross = np.where(both & (t > 0) & (t < 1), fa + sa * t, -np.inf)
        lone_a = np.where(ok_a & ~ok_b & (sa > 0), fa + sa, -np.inf)
        lone_b = np.where(ok_b & ~ok_a & (sb > 0), fb + sb, -np.inf)
        peak = np.maximum(np.maximum(cross, lone_a), lone_b)
        return np.where(np.isfinite(top) & np.isfinite(peak), np.maximum(peak - top, 0.0), 0.0)


def _sub_cells(F: np.ndarray, h: float, fi: np.ndarray, fj: np.ndarray, check: int) -> np.ndarray:
    """``(len(fi), check, check)`` heights bounding the design over the fine sub-cells of the
    cells ``(fi, fj)``: per sub-cell the largest of its corner samples plus how far a ridge
    can rise between them along x and along y (:func:`_ridge_excess` on its edges); NaN where
    no corner has a sample."""
    nfx, nfy = F.shape
    P = np.full((nfx + 4, nfy + 4), np.nan)
    P[2:-2, 2:-2] = F
    a, b = np.meshgrid(np.arange(check), np.arange(check), indexing="ij")
    I = (fi[:, None, None] * check + a[None]).ravel() + 2
    J = (fj[:, None, None] * check + b[None]).ravel() + 2
    wall = WALL * h
    ex = np.zeros(I.size)
    ey = np.zeros(I.size)
    for d in (0, 1):
        # the x-edge at row J + d: samples I, I + 1; beyond them I - 1 and I + 2
        ex = np.maximum(ex, _ridge_excess(P[I, J + d], P[I + 1, J + d], P[I, J + d] - P[I - 1, J + d],
                                          P[I + 1, J + d] - P[I + 2, J + d], wall))
        ey = np.maximum(ey, _ridge_excess(P[I + d, J], P[I + d, J + 1], P[I + d, J] - P[I + d, J - 1],
                                          P[I + d, J + 1] - P[I + d, J + 2], wall))
    corners = np.stack([P[I, J], P[I + 1, J], P[I, J + 1], P[I + 1, J + 1]])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # an empty sub-cell: NaN, no surface
        return (np.nanmax(corners, axis=0) + ex + ey).reshape(fi.size, check, check)


def drop_bound(bs: BoundingSurface, cutter: Any, x: np.ndarray, y: np.ndarray, *, eps: float = EPS,
               min_size: float = 1e-4) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Cutter-location heights over a bounding surface: ``(cl, cx, cy, kept)``.

    ``cl`` is NaN where no node or patch lies under the cutter; ``(cx, cy)`` is the contact
    (the best exact point, or the centre of the cell whose bound was kept, pulled onto the
    disk); ``kept`` counts
    the cells whose bound was kept without being resolved to ``eps`` (0 on exact cells but for
    a contact sharper than ``min_size``).
    """
    from ..sim.tools import parse_tool_spec
    from . import _bound_kernels as BK

    cut = parse_tool_spec(cutter) if isinstance(cutter, str) else cutter
    qx = np.ascontiguousarray(np.ravel(x), dtype=np.float64)
    qy = np.ascontiguousarray(np.ravel(y), dtype=np.float64)
    n = qx.size
    out = np.empty(n)
    cx = np.empty(n)
    cy = np.empty(n)
    kept = np.empty(n)
    if n:
        BK.drop_bound(bs.nets, bs.cmax, bs.margin, bs.sub, bs.subidx, bs.z, bs.x0, bs.y0, bs.dx, bs.dy, bs.bcell, bs.bnode, _B,
                      cut.code, cut.radius, cut.corner_radius, float(eps), float(min_size), qx, qy, out, cx, cy,
                      kept, max(16, min(1024, n // 64 + 1)))
    out[~np.isfinite(out)] = np.nan
    # a kept cell's centre may lie beyond the rim: its contact is on the disk
    r = np.hypot(cx - qx, cy - qy)
    far = r > cut.radius
    if far.any():
        f = cut.radius / r[far]
        cx[far] = qx[far] + (cx[far] - qx[far]) * f
        cy[far] = qy[far] + (cy[far] - qy[far]) * f
    return out, cx, cy, kept.astype(np.int64)
