"""CZ-maps (core z-maps) along feature curves: paper 004 §3.1, Procedure Construct_CZmap.

Along every feature polyline (VW curves traced on the master z-map, SE curves from the
part's edges) a series of rotated local domains is laid: each is a :class:`zmap.ZMap` with
a local frame whose x-axis follows a run of the curve, with grid intervals

    ``delta_y = tol`` across the curve and ``delta_x = k * delta_y`` along it,
    ``k = 1 / tan(theta_x)``  (``theta_x`` = 20 degrees gives ``k`` about 2.75),

so that the curve, which stays within ``theta_x`` of the local x-axis, moves at most
``delta_y`` sideways over one ``delta_x``. Consecutive segments are merged into one domain
while each stays within ``theta_x`` of the run's chord and the run stays within one base
interval of it, which keeps the number of CZ-maps small. A domain covers the run's band:
the curve's sideways spread plus ``margin`` base intervals on each side (and beyond each
end), so the cells where the base z-map's interpolation is spoiled by the feature lie inside.
Heights come from the ``heights(x, y)`` callable, the same exact sampler as the converter.
"""

from __future__ import annotations

import math
from typing import Callable, Sequence

import numpy as np

from ..grid import ZMap
from ..gridspec import lines_covering

__all__ = ["build_cz", "cz_intervals", "cz_layout", "split_runs"]

#: most grid points a single CZ-map may hold (a longer run is split)
MAX_POINTS = 4_000_000


def cz_intervals(tol: float, theta_x: float) -> tuple[float, float]:
    """``(delta_x, delta_y)`` of a CZ-map: ``delta_y = tol``, ``delta_x = tol / tan(theta_x)``.

    Examples
    --------
    >>> [round(v, 4) for v in cz_intervals(0.01, math.radians(20))]
    [0.0275, 0.01]
    """
    tol = float(tol)
    theta_x = float(theta_x)
    if not (math.isfinite(tol) and tol > 0):
        raise ValueError(f"tol must be a positive length in mm, got {tol!r}")
    if not (0.0 < theta_x <= math.pi / 4):
        raise ValueError(f"theta_x must be in (0, pi/4] radians (k = 1/tan(theta_x) >= 1), got {theta_x!r}")
    return tol / math.tan(theta_x), tol


def split_runs(curve: np.ndarray, theta_x: float, max_dev: float, max_len: float = math.inf) -> list[tuple[int, int]]:
    """Split a polyline into runs ``(i, j)`` (points ``i..j``) that each fit one CZ domain.

    A run grows while every segment in it stays within ``theta_x`` of the chord from its
    first to its last point, every point lies within ``max_dev`` of that chord, and the
    chord is at most ``max_len`` long. Consecutive runs share their end point.

    Examples
    --------
    >>> c = np.array([[0, 0], [1, 0], [2, 0.1], [3, 0], [3, 1], [3, 2.0]])
    >>> split_runs(c, math.radians(20), 0.5)
    [(0, 3), (3, 5)]
    """
    c = np.asarray(curve, dtype=np.float64)
    n = len(c)
    if n < 2:
        return []
    cos_t = math.cos(theta_x)
    runs = []
    i = 0
    while i < n - 1:
        j = i + 1
        while j + 1 < n:
            seg = c[i:j + 2]
            chord = seg[-1] - seg[0]
            L = math.hypot(chord[0], chord[1])
            if L == 0.0 or L > max_len:
                break
            e = chord / L
            d = np.diff(seg, axis=0)
            dl = np.hypot(d[:, 0], d[:, 1])
            ok_angle = np.all((d @ e) >= cos_t * dl - 1e-12)
            lat = np.abs((seg - seg[0]) @ np.array([-e[1], e[0]]))
            if not (ok_angle and lat.max() <= max_dev):
                break
            j += 1
        runs.append((i, j))
        i = j
    return runs


def _domain(pts: np.ndarray, along: np.ndarray | None, pad: float, ddx: float, ddy: float) -> tuple:
    """Frame and grid ``(angle, origin, x0, y0, nx, ny)`` of the band around ``pts``."""
    if along is None:
        e = np.array([1.0, 0.0])
    else:
        e = along / np.hypot(*along)
    nrm = np.array([-e[1], e[0]])
    o = pts[0]
    lx = (pts - o) @ e
    ly = (pts - o) @ nrm
    x0, x1 = lx.min() - pad, lx.max() + pad
    y0, y1 = ly.min() - pad, ly.max() + pad
    nx, ny = lines_covering(x0, x1, ddx), lines_covering(y0, y1, ddy)
    return math.atan2(e[1], e[0]), (float(o[0]), float(o[1])), float(x0), float(y0), nx, ny


def build_cz(base: ZMap, heights: Callable[[np.ndarray, np.ndarray], np.ndarray], *, tol: float,
             curves: Sequence[np.ndarray] | None = None, theta_x: float = math.radians(20.0),
             eps_r: float | None = None, margin: float = 2.0) -> list[ZMap]:
    """Procedure Construct_CZmap: CZ-maps along the feature curves of a master z-map.

    Parameters
    ----------
    base : ZMap
        Master (base) z-map; its intervals bound the CZ-map's (``delta_x < dx, dy``).
    heights : callable
        ``heights(x, y) -> z`` at world xy (arrays), NaN where there is no surface: the
        exact sampler (:func:`cad_io.sampler.height_function`).
    tol : float
        Tolerance in mm: the CZ-maps' ``delta_y``. Must be below the base intervals.
    curves : sequence of ndarray (n, 2), optional
        Feature polylines in world xy (VW and SE curves). Default: the VW curves traced on
        ``base`` with slope threshold ``eps_r`` (:func:`zmap.features.vertical_wall_curves`).
    theta_x : float
        Largest angle (radians) between the curve and a domain's x-axis; ``k = 1/tan``.
    eps_r : float, optional
        Slope threshold for the default VW curves; default
        :func:`zmap.features.default_eps_r`.
    margin : float
        Half-width added on each side of (and beyond each end of) a run, in base intervals.

    Returns
    -------
    list of ZMap
        One per domain, each with ``angle``/``origin`` set, ``dx = delta_x``,
        ``dy = delta_y``; ``meta`` has ``kind='cz'``, the curve and run it follows.

    Raises
    ------
    ValueError
        ``tol`` not below the base grid intervals, bad ``theta_x``.

    Examples
    --------
    >>> wall = lambda x, y: np.where(x < 2.02, 0.0, 5.0)
    >>> base = ZMap.from_function(wall, (0, 0, 4, 2), 0.5)
    >>> cz = build_cz(base, wall, tol=0.05, curves=[np.array([[2.02, 0.0], [2.02, 2.0]])])
    >>> len(cz), round(cz[0].dy, 3), round(math.degrees(cz[0].angle), 1)
    (1, 0.05, 90.0)
    """
    out: list[ZMap] = []
    for ci, (i, j), (angle, origin, x0, y0, nx, ny), ddx, ddy in _frames(base, tol, curves, theta_x, eps_r, margin):
        xs = x0 + ddx * np.arange(nx)
        ys = y0 + ddy * np.arange(ny)
        LX, LY = np.meshgrid(xs, ys, indexing="ij")
        ca, sa = math.cos(angle), math.sin(angle)
        WX = origin[0] + ca * LX - sa * LY
        WY = origin[1] + sa * LX + ca * LY
        z = np.asarray(heights(WX, WY), dtype=np.float64).reshape(nx, ny)
        out.append(ZMap(x0, y0, ddx, ddy, z, angle=angle, origin=origin,
                        meta={"kind": "cz", "curve": ci, "run": [int(i), int(j)], "tol": float(tol),
                              "theta_x": float(theta_x)}))
    return out


def cz_layout(base: ZMap, *, tol: float, curves: Sequence[np.ndarray] | None = None,
              theta_x: float = math.radians(20.0), eps_r: float | None = None, margin: float = 2.0) -> np.ndarray:
    """The grid shapes :func:`build_cz` would sample, without sampling (same arguments).

    Returns
    -------
    ndarray of shape (D, 2), int64
        ``(nx, ny)`` of each CZ domain: the CZ model stores ``8 * sum(nx * ny)`` bytes of
        heights and samples that many points.

    Examples
    --------
    >>> wall = lambda x, y: np.where(x < 2.02, 0.0, 5.0)
    >>> base = ZMap.from_function(wall, (0, 0, 4, 2), 0.5)
    >>> cz_layout(base, tol=0.05, curves=[np.array([[2.02, 0.0], [2.02, 2.0]])]).tolist()
    [[31, 41]]
    """
    return np.array([[nx, ny] for _c, _r, (_a, _o, _x0, _y0, nx, ny), _dx, _dy
                     in _frames(base, tol, curves, theta_x, eps_r, margin)], dtype=np.int64).reshape(-1, 2)


def _frames(base, tol, curves, theta_x, eps_r, margin):
    """Yield ``(curve index, run, (angle, origin, x0, y0, nx, ny), delta_x, delta_y)`` per CZ domain."""
    ddx, ddy = cz_intervals(tol, theta_x)
    h = max(base.dx, base.dy)
    if not tol < min(base.dx, base.dy):
        raise ValueError(f"tol={tol!r} mm must be smaller than the base grid interval "
                         f"(dx={base.dx!r}, dy={base.dy!r})")
    ddx = min(ddx, 0.999 * min(base.dx, base.dy))
    margin = float(margin)
    if not (math.isfinite(margin) and margin >= 0):
        raise ValueError(f"margin must be a number of base intervals >= 0, got {margin!r}")
    if curves is None:
        from ..features import default_eps_r, vertical_wall_curves

        if eps_r is None:
            eps_r = default_eps_r(tol, base.dx, base.dy)
        curves = vertical_wall_curves(base, eps_r)
    pad = margin * h
    # a run is at most as long as MAX_POINTS allows across a band of the widest spread
    ny_max = (2 * (pad + h)) / ddy + 2
    max_len = max(MAX_POINTS / ny_max * ddx - 2 * pad, h)
    for ci, curve in enumerate(curves):
        c = np.asarray(curve, dtype=np.float64).reshape(-1, 2)
        c = c[np.all(np.isfinite(c), axis=1)]
        if len(c) == 0:
            continue
        # drop repeated points (closed loops repeat their first point at the end)
        keep = np.concatenate([[True], np.hypot(*np.diff(c, axis=0).T) > 1e-12])
        c = c[keep]
        if len(c) == 1:
            frames = [((0, 0), _domain(c, None, pad, ddx, ddy))]
        else:
            frames = [((i, j), _domain(c[i:j + 1], c[j] - c[i], pad, ddx, ddy))
                      for i, j in split_runs(c, theta_x, h, max_len)]
        for (i, j), frame in frames:
            yield ci, (i, j), frame, ddx, ddy
