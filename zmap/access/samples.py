"""Surface samples for the visibility voxel map, and those of a design that gives heights.

:class:`Samples` is what :meth:`VoxelMap.from_samples <zmap.access.build.VoxelMap.from_samples>`
folds into voxels: points, outward normals, the largest concave curvature, a surface id and
the area each sample stands for. ``cad_io.access.surface_samples`` makes them from a part's
exact faces; :func:`design_samples` makes them from anything :func:`zmap.design.as_design`
takes (a z-map, a tiled z-map, a precision model, a registered part, a ``heights(x, y)``
callable with bounds): the top-most surface ``z = h(x, y)`` seen from +z, one surface (id 0),
normals ``(-h_x, -h_y, 1)`` and curvatures from the heights' central differences.

A steep stretch (a wall between two z-map nodes) is sampled more densely across its slope, so
that neighbouring samples stay about ``step`` apart along the surface, as on a part's face.

Examples
--------
>>> import numpy as np
>>> from zmap import ZMap
>>> plane = ZMap.from_function(lambda x, y: 0.5 * x, (0, 0, 4, 4), 0.5)
>>> s = design_samples(plane, 0.25)
>>> bool(np.allclose(s.normals, [-0.5, 0, 1] / np.sqrt(1.25)))
True
>>> round(float(s.weight.sum()), 6), round(16 * 1.25 ** 0.5, 6)  # the slope's area, mm^2
(17.888544, 17.888544)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Samples", "design_samples", "largest_curvature", "MAX_SUBDIVISION"]

#: most sub-samples across one sampling cell of a steep stretch (a slope of about 256)
MAX_SUBDIVISION = 256


@dataclass
class Samples:
    """Surface samples: ``points`` (n, 3) mm, outward unit ``normals`` (n, 3), ``curvature``
    (n,) largest concave principal curvature (1/mm, negative where convex), ``face`` (n,)
    surface id, ``weight`` (n,) area each stands for (mm^2)."""

    points: np.ndarray
    normals: np.ndarray
    curvature: np.ndarray
    face: np.ndarray
    weight: np.ndarray

    def __len__(self) -> int:
        return int(len(self.points))


def _cells(lo: float, hi: float, step: float) -> tuple[np.ndarray, float]:
    """Centres of the fewest equal cells no wider than ``step`` that tile [lo, hi], and their width."""
    n = max(1, int(np.ceil((hi - lo) / step - 1e-9)))
    h = (hi - lo) / n
    return lo + (np.arange(n) + 0.5) * h, h


def _derivatives(heights, x: np.ndarray, y: np.ndarray, e: np.ndarray,
                 second: bool = True) -> tuple[np.ndarray, ...]:
    """``(z, h_x, h_y, h_xx, h_xy, h_yy)`` at (x, y) by central differences of spacing ``e``;
    one-sided where a neighbour has no surface, 0 where neither side has. ``second=False``:
    ``(z, h_x, h_y)`` alone, from five height evaluations instead of nine."""
    def at(dx: float, dy: float) -> np.ndarray:
        return np.asarray(heights(x + dx * e, y + dy * e), dtype=np.float64)

    z = at(0, 0)
    xp, xm, yp, ym = at(1, 0), at(-1, 0), at(0, 1), at(0, -1)

    def slope(p: np.ndarray, m: np.ndarray) -> np.ndarray:
        both = np.isfinite(p) & np.isfinite(m)
        out = np.where(both, (p - m) / (2 * e), 0.0)
        out = np.where(~both & np.isfinite(p), (p - z) / e, out)
        return np.where(~both & ~np.isfinite(p) & np.isfinite(m), (z - m) / e, out)

    if not second:
        return z, slope(xp, xm), slope(yp, ym)

    def bend(p: np.ndarray, m: np.ndarray) -> np.ndarray:
        return np.where(np.isfinite(p) & np.isfinite(m), (p - 2 * z + m) / (e * e), 0.0)

    pp, pm, mp, mm = at(1, 1), at(1, -1), at(-1, 1), at(-1, -1)
    corners = np.isfinite(pp) & np.isfinite(pm) & np.isfinite(mp) & np.isfinite(mm)
    hxy = np.where(corners, (pp - pm - mp + mm) / (4 * e * e), 0.0)
    return z, slope(xp, xm), slope(yp, ym), bend(xp, xm), hxy, bend(yp, ym)


def largest_curvature(E, F, G, L, M, N) -> np.ndarray:
    """Largest principal curvature from the first (E, F, G) and second (L, M, N) fundamental
    forms, the second taken along the chosen normal: positive where the surface bends toward
    it (concave seen from outside for an outward normal); NaN where the first form is singular."""
    det = E * G - F * F
    with np.errstate(divide="ignore", invalid="ignore"):
        H = (E * N - 2 * F * M + G * L) / (2 * det)
        K = (L * N - M * M) / det
        return H + np.sqrt(np.maximum(H * H - K, 0.0))


def _concave_curvature(p, q, r, s, t) -> np.ndarray:
    """:func:`largest_curvature` of ``z = h(x, y)`` toward its upward normal (positive where the
    surface bends up, concave seen from above), from ``h_x, h_y, h_xx, h_xy, h_yy``."""
    w = np.sqrt(1 + p * p + q * q)
    return largest_curvature(1 + p * p, p * q, 1 + q * q, r / w, s / w, t / w)


def design_samples(design, step: float, *, bounds: tuple | None = None) -> Samples:
    """Samples of a design's top-most surface ``z = h(x, y)`` at about ``step`` mm apart.

    Parameters
    ----------
    design
        A :class:`~zmap.ZMap`, :class:`~zmap.tiled.TiledZMap`,
        :class:`~zmap.model.PrecisionModel`, a registered type (a STEP part through cad_io) or
        a ``heights(x, y)`` callable (then ``bounds`` is needed).
    step : float
        Sample spacing, mm (the voxel map's d'); cells are the fewest equal ones no wider,
        and a steep cell is split across its slope until its samples are no more than about
        ``step`` apart along the surface (at most :data:`MAX_SUBDIVISION` per side).
    bounds : (xmin, ymin, xmax, ymax), optional
        The region sampled (default: the design's).

    Returns
    -------
    Samples
        At each cell's centre where the design has a surface: the point, the upward unit
        normal, the largest concave curvature, surface id 0 and the cell's surface area.

    Raises
    ------
    ValueError
        A step that is not a positive number, a design without bounds and no ``bounds``, or a
        region with no surface at all.
    """
    from ..design import as_design

    d = as_design(design)
    step = float(step)
    if not (np.isfinite(step) and step > 0):
        raise ValueError(f"the sampling step must be a positive number of mm, got {step!r}")
    box = bounds if bounds is not None else d.bounds
    if box is None:
        raise ValueError(f"a {d.kind} design has no extent of its own: give bounds=(xmin, ymin, xmax, ymax)")
    x0, y0, x1, y1 = (float(v) for v in box)
    if not (np.isfinite([x0, y0, x1, y1]).all() and x1 > x0 and y1 > y0):
        raise ValueError(f"bounds must be finite with xmax > xmin and ymax > ymin, got {box!r}")
    cx, hx = _cells(x0, x1, step)
    cy, hy = _cells(y0, y1, step)
    X, Y = (a.ravel() for a in np.meshgrid(cx, cy, indexing="ij"))
    # the mean slope over each cell (differences across its width) says how steep it is
    z, p, q = _derivatives(d.heights, X, Y, np.full(X.shape, 0.5 * min(hx, hy)), second=False)
    p, q = np.nan_to_num(p), np.nan_to_num(q)
    # sub-samples across a steep cell: its rise over the cell, in steps along the surface
    mx = np.clip(np.ceil(hx * np.sqrt(1 + p * p) / step - 1e-9), 1, MAX_SUBDIVISION).astype(np.int64)
    my = np.clip(np.ceil(hy * np.sqrt(1 + q * q) / step - 1e-9), 1, MAX_SUBDIVISION).astype(np.int64)
    keep = np.isfinite(z) | (mx > 1) | (my > 1)
    X, Y, mx, my = X[keep], Y[keep], mx[keep], my[keep]
    n = mx * my
    cell = np.repeat(np.arange(len(X)), n)
    local = np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)
    i, j = local // my[cell], local % my[cell]
    sx, sy = hx / mx[cell], hy / my[cell]
    xs = X[cell] - hx / 2 + (i + 0.5) * sx
    ys = Y[cell] - hy / 2 + (j + 0.5) * sy
    z, p, q, r, s, t = _derivatives(d.heights, xs, ys, 0.25 * np.minimum(sx, sy))
    ok = np.isfinite(z)
    if not ok.any():
        raise ValueError(f"the {d.kind} design has no surface in {(x0, y0, x1, y1)}")
    xs, ys, z, p, q, r, s, t, sx, sy = (a[ok] for a in (xs, ys, z, p, q, r, s, t, sx, sy))
    w = np.sqrt(1 + p * p + q * q)
    normals = np.column_stack([-p / w, -q / w, 1 / w])
    return Samples(np.column_stack([xs, ys, z]), normals, _concave_curvature(p, q, r, s, t),
                   np.zeros(len(xs), dtype=np.int64), sx * sy * w)

