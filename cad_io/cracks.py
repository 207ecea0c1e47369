"""Cracks narrower than the tolerance, bridged in the heights the precision models are built from.

Faces that meet only within the tolerance their file gives their edges leave gaps in the
nominal B-rep: trj8_b1-ec-214's faces 351 and 42 (edges 0.30 mm) leave a crack about
0.015 mm wide along their seam, through which the exact sampler (and OCC's ray cast) sees a
face 46 mm below. The master z-map's nodes keep those heights (they are OCC's), but an EZ
model built on them followed every e-point and test point that fell into the crack, and
its patches made funnels 0.6 mm from the part between them. A point whose height lies
more than ``tol`` below both heights a distance ``w`` to either side of it (along x, y or
a diagonal) is in a crack; it takes the mean of those two heights, the surface across the
crack. ``w = 2 tol`` first: a straight crack up to about ``1.85 tol`` wide is bridged
wherever it is met, every point of it within ``tol`` (3D) of the crack's rims. Wider
cracks are bridged where the faces at their rims reach across them within the tolerance
their file gives their edges (the shape as valid within its tolerances has no crack
there); a slot wider than that is a feature and is kept.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from zmap.grid import ZMap

__all__ = ["bridge_cracks", "span_node_cracks"]


def _cell_floor(base: ZMap, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Lowest node height of the base cell holding each point, over the corners with a
    surface (NaN outside the map or where no corner has one)."""
    lx, ly = base.world_to_local(x, y) if base.has_frame else (x, y)
    fi = (lx - base.x0) / base.dx
    fj = (ly - base.y0) / base.dy
    inside = (fi >= 0) & (fj >= 0) & (fi <= base.nx - 1) & (fj <= base.ny - 1)
    i = np.clip(np.floor(np.nan_to_num(fi)).astype(np.int64), 0, max(base.nx - 2, 0))
    j = np.clip(np.floor(np.nan_to_num(fj)).astype(np.int64), 0, max(base.ny - 2, 0))
    z = base.z
    i1 = np.minimum(i + 1, base.nx - 1)
    j1 = np.minimum(j + 1, base.ny - 1)
    # a corner without surface (the part's outline crosses the cell) does not count
    floor = np.fmin(np.fmin(z[i, j], z[i1, j]), np.fmin(z[i, j1], z[i1, j1]))
    return np.where(inside, floor, np.nan)


def bridge_cracks(sampler: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]], base: ZMap,
                  x: np.ndarray, y: np.ndarray, z: np.ndarray, tol: float, face_tol: np.ndarray | None = None,
                  width: float | None = None) -> tuple[np.ndarray, int]:
    """Heights ``z`` at ``(x, y)`` with the points in cracks between faces bridged.

    Only points more than ``tol`` below every node of their base cell are probed: a point by
    a real wall has the wall's foot among its cell's nodes, a point in a hole or crack inside
    a cell does not. Each is probed at ``w = width`` to either side along x, y and the two
    diagonals (eight heights); where no pair of probes stands more than ``tol`` above it on
    both sides, ``w`` doubles, as long as the crack such a pair would span (at most ``2 w``
    wide) is within the tolerance of the faces at its rims (``2 w <= t_a + t_b``: each face
    reaches its edges' tolerance beyond its trim curve). The highest mean of a pair that
    stands above the point on both sides is its height.

    Parameters
    ----------
    sampler : callable
        ``sampler(x, y) -> (z, face)``: exact heights and the face that gave each (-1 none).
    base : ZMap
        The master z-map the model refines (the cells' node heights).
    x, y, z : ndarray
        The points and their heights from ``sampler`` (same shape).
    tol : float
        Tolerance (mm): how far below its neighbours a point must be to be in a crack.
    face_tol : ndarray, optional
        Each face's edge tolerance in the file (mm); None: only cracks up to ``2 width``
        (the first probes) are bridged.
    width : float, optional
        First probe distance (mm); default ``2 tol``.

    Returns
    -------
    (ndarray, int)
        The heights (a copy where any point was bridged) and the number of points bridged.

    Examples
    --------
    >>> def top(x, y):
    ...     z = np.where(np.abs(x - 1.203) < 0.006, -5.0, 1.0 + 0 * y)
    ...     return z, np.zeros(z.shape, dtype=int)
    >>> base = ZMap.from_function(lambda x, y: top(x, y)[0], (0, 0, 2, 2), 0.5)
    >>> x = np.array([1.2, 1.206, 0.4]); y = np.array([0.3, 0.3, 0.3])
    >>> z, n = bridge_cracks(top, base, x, y, top(x, y)[0], 0.01)
    >>> z.tolist(), n
    ([1.0, 1.0, 1.0], 2)
    """
    w = 2.0 * tol if width is None else float(width)
    zf = np.asarray(z, dtype=np.float64).ravel()
    xf = np.asarray(x, dtype=np.float64).ravel()
    yf = np.asarray(y, dtype=np.float64).ravel()
    with np.errstate(invalid="ignore"):
        todo = np.flatnonzero(np.isfinite(zf) & (zf < _cell_floor(base, xf, yf) - tol))
    if todo.size == 0:
        return np.asarray(z), 0
    out, n_bridged = _span(sampler, xf, yf, zf, todo, tol, face_tol, w)
    if n_bridged == 0:
        return np.asarray(z), 0
    return out.reshape(np.shape(z)), n_bridged


def _span(sampler, xf: np.ndarray, yf: np.ndarray, zf: np.ndarray, todo: np.ndarray, tol: float,
          face_tol, w: float) -> tuple[np.ndarray, int]:
    """Probe the points ``todo`` of ``(xf, yf, zf)`` (see :func:`bridge_cracks`): a copy of ``zf``
    with those in cracks spanned, and their number.

    A pair of probes spans the point when both stand more than ``tol`` above it and closer to
    each other than to it (``|a - b| <= (min(a, b) - z) / 2``): the rims of one crack, not
    one rim and a probe that fell into the crack elsewhere (trj8's crack through a base node).
    """
    ft = np.zeros(0) if face_tol is None else np.asarray(face_tol, dtype=np.float64)
    widest = w if ft.size == 0 else max(w, float(ft.max()))
    out = zf.copy()
    n_bridged = 0
    first = True
    while todo.size and (first or w <= widest):
        xs, ys, zs = xf[todo], yf[todo], zf[todo]
        # four lines through the point (x, y and the diagonals): the one nearest the crack's
        # normal is within 22.5 degrees of it
        c45 = w * np.sqrt(0.5)
        off = ((w, 0.0), (0.0, w), (c45, c45), (c45, -c45))
        px = np.concatenate([xs + sg * ox for ox, _ in off for sg in (-1.0, 1.0)])
        py = np.concatenate([ys + sg * oy for _, oy in off for sg in (-1.0, 1.0)])
        pz, pf = sampler(px, py)
        pz = np.asarray(pz, dtype=np.float64).reshape(4, 2, -1)
        with np.errstate(invalid="ignore"):
            low = np.fmin(pz[:, 0], pz[:, 1])
            across = (low > zs + tol) & (np.abs(pz[:, 0] - pz[:, 1]) <= 0.5 * (low - zs))
        if not first:
            # a crack up to 2 w wide: only where the rims' faces reach across it
            pf = np.asarray(pf, dtype=np.int64).reshape(4, 2, -1)
            rims = np.where(pf >= 0, ft[np.clip(pf, 0, max(ft.size - 1, 0))], 0.0) if ft.size else np.zeros(pf.shape)
            across &= 2.0 * w <= rims[:, 0] + rims[:, 1]
        mean = np.where(across, 0.5 * (pz[:, 0] + pz[:, 1]), -np.inf)
        hit = across.any(axis=0)
        out[todo[hit]] = mean.max(axis=0)[hit]
        n_bridged += int(hit.sum())
        todo = todo[~hit]
        w *= 2.0
        first = False
    return out, n_bridged


def span_node_cracks(sampler, base: ZMap, tol: float, face_tol: np.ndarray | None = None,
                     width: float | None = None) -> tuple[ZMap, int]:
    """A copy of ``base`` whose nodes in cracks take the surface across them.

    A node lower by more than ``tol`` than both its neighbours along x, or both along y, is
    probed as :func:`bridge_cracks` probes a point. The master z-map keeps OCC's heights;
    the precision model refines this copy, so that a crack through a node (trj8: the node
    (220.244, -65.0) at -12.5 mm between faces at 1.6 mm) makes no funnel in its cells.

    Returns
    -------
    (ZMap, int)
        ``base`` itself where no node was spanned, else a copy; the number of nodes spanned.
    """
    z = base.z
    nb = np.full((4,) + z.shape, np.nan)
    nb[0, 1:, :] = z[:-1, :]
    nb[1, :-1, :] = z[1:, :]
    nb[2, :, 1:] = z[:, :-1]
    nb[3, :, :-1] = z[:, 1:]
    with np.errstate(invalid="ignore"):
        # below both neighbours along x, or both along y (a crack along a grid line has the
        # node's neighbours along it in the crack too)
        pit = ((z < nb[0] - tol) & (z < nb[1] - tol)) | ((z < nb[2] - tol) & (z < nb[3] - tol))
        todo = np.flatnonzero((np.isfinite(z) & pit).ravel())
    if todo.size == 0:
        return base, 0
    gx, gy = base.grid_points()
    xf = np.asarray(gx, dtype=np.float64).ravel()
    yf = np.asarray(gy, dtype=np.float64).ravel()
    w = 2.0 * tol if width is None else float(width)
    out, n = _span(sampler, xf, yf, z.ravel().astype(np.float64), todo, tol, face_tol, w)
    if n == 0:
        return base, 0
    spanned = base.copy()
    spanned.z = out.reshape(z.shape).astype(z.dtype)
    return spanned, n
